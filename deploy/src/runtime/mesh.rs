//! All Zenoh session setup, in one function fed by one options struct.
//!
//! Processes of a deployment are peers in a full mesh: each listens on its
//! own endpoint and connects to every other's. Peers in Zenoh 1.10 do not
//! relay for one another, so on a LAN every host must reach every other
//! host's endpoints directly (the alternative, one router with clients, puts
//! every message through one process). Multicast scouting is off: it is
//! unavailable in many networks and in CI; the topology file is the truth.
//! Clients (the query CLI, Python) connect to the coordinator's endpoint.
//!
//! Links close at once (Zenoh's TCP `SO_LINGER` is 0, set when Zenoh is
//! compiled, in `.cargo/config.toml`): a lingering close to a cut-off host
//! blocked every incoming message for 10 s (docs/guide/lan.md).
//!
//! A secured deployment ([`super::security`]) adds mutual TLS — every
//! endpoint becomes `quic/` (TLS 1.3 inside QUIC; why not Zenoh's `tls/`
//! link: [`secured_endpoint`]), each side shows its certificate — and, in
//! its processes, the access-control rules generated from the topology.
//! Zenoh's QUIC link reads the same `transport/link/tls` settings.

use super::security::tls::secured_endpoint;
use super::security::Tls;
use anyhow::{anyhow, Result};
use zenoh::{Config, Session};

#[derive(Debug, Clone, Default)]
pub struct MeshOptions {
    /// "peer" for deployment processes, "client" for query tools.
    pub client: bool,
    pub listen: Vec<String>,
    pub connect: Vec<String>,
    /// Mutual TLS with these files; None = plain TCP.
    pub tls: Option<Tls>,
    /// Zenoh's `access_control` section (see
    /// [`super::security::rules::access_control`]); None = no rules.
    pub access_control: Option<serde_json::Value>,
    /// Send every message the moment it is ready, never held back to share
    /// a batch with the next. For a process that only answers questions
    /// (the coordinator): Zenoh's adaptive batching held a 200 kB answer
    /// back up to a millisecond more (p99 of a raw 200 kB get on loopback
    /// 2.7 ms batched, 0.6 ms not), and there is no stream to batch.
    pub unbatched: bool,
    /// A client that cannot reach its endpoint tries again for this long
    /// before it gives up (None: it gives up at once, as a one-off command
    /// should). For a service started beside the deployment (`idmesh
    /// web`), which may come up before the coordinator listens.
    pub connect_patience: Option<std::time::Duration>,
}

/// The endpoints of a client's `--connect`: one, or several separated by
/// commas (a coordinator and its replicas; Zenoh's client keeps to one
/// and moves to another when that one is gone).
pub(crate) fn endpoint_list(text: &str) -> Vec<String> {
    text.split(',')
        .map(str::trim)
        .filter(|e| !e.is_empty())
        .map(str::to_string)
        .collect()
}

/// How soon a patient client tries its endpoint again, at first and at
/// most (doubling in between).
const RETRY_FIRST_MS: u64 = 100;
const RETRY_MOST_MS: u64 = 1000;

/// How long a one-off client with several endpoints waits for one to
/// open before it tries the next (a LAN link opens in milliseconds).
const ONE_OFF_OPEN_TIMEOUT_MS: u64 = 2000;

pub(crate) fn config(options: &MeshOptions) -> Result<Config> {
    let mut config = Config::default();
    let set = |config: &mut Config, key: &str, value: String| {
        config
            .insert_json5(key, &value)
            .map_err(|e| anyhow!("zenoh config {key} = {value}: {e}"))
    };
    let mode = if options.client { "client" } else { "peer" };
    set(&mut config, "mode", format!("{mode:?}"))?;
    let endpoints = |list: &[String]| -> Result<String> {
        let list = match options.tls {
            Some(_) => list
                .iter()
                .map(|e| secured_endpoint(e))
                .collect::<Result<_, _>>()?,
            None => list.to_vec(),
        };
        Ok(serde_json::to_string(&list)?)
    };
    set(&mut config, "listen/endpoints", endpoints(&options.listen)?)?;
    set(
        &mut config,
        "connect/endpoints",
        endpoints(&options.connect)?,
    )?;
    set(&mut config, "scouting/multicast/enabled", "false".into())?;
    if let Some(patience) = options.connect_patience {
        set(
            &mut config,
            "connect/timeout_ms",
            patience.as_millis().to_string(),
        )?;
        set(
            &mut config,
            "connect/retry",
            format!("{{period_init_ms: {RETRY_FIRST_MS}, period_max_ms: {RETRY_MOST_MS}}}"),
        )?;
    }
    if options.client && options.connect.len() > 1 && options.connect_patience.is_none() {
        // A one-off client given several coordinators opens its session
        // on the first that answers, in turn: on one whose host is gone
        // (no refusal comes back) it would wait out the default open
        // timeout, 10 s, before it tried the next.
        set(
            &mut config,
            "transport/unicast/open_timeout",
            ONE_OFF_OPEN_TIMEOUT_MS.to_string(),
        )?;
    }
    if options.unbatched {
        set(
            &mut config,
            "transport/link/tx/queue/batching/enabled",
            "false".into(),
        )?;
    }
    if let Some(tls) = &options.tls {
        // One certificate for both ends of a link, so a peer has the same
        // common name whichever of the two opened it.
        let (ca, cert, key) = (path(&tls.ca)?, path(&tls.cert)?, path(&tls.key)?);
        for (field, value) in [
            ("root_ca_certificate", ca),
            ("listen_certificate", cert),
            ("listen_private_key", key),
            ("connect_certificate", cert),
            ("connect_private_key", key),
        ] {
            set(
                &mut config,
                &format!("transport/link/tls/{field}"),
                serde_json::to_string(value)?,
            )?;
        }
        set(&mut config, "transport/link/tls/enable_mtls", "true".into())?;
        set(
            &mut config,
            "transport/link/tls/verify_name_on_connect",
            tls.verify_names.to_string(),
        )?;
    }
    if let Some(rules) = &options.access_control {
        set(&mut config, "access_control", rules.to_string())?;
    }
    Ok(config)
}

fn path(p: &std::path::Path) -> Result<&str> {
    p.to_str()
        .ok_or_else(|| anyhow!("{}: Zenoh takes UTF-8 paths only", p.display()))
}

/// Answers `key` at once with `name`, from Zenoh's own thread: the raw
/// round trip to this process, with none of its work in it. Health checks
/// and the bench (the floor a query is compared with) use it.
pub(crate) async fn answer_pings(session: &Session, key: String, name: String) -> Result<()> {
    use zenoh::Wait;
    let reply_key = key.clone();
    session
        .declare_queryable(&key)
        .callback(move |query| {
            if let Err(e) = query.reply(&reply_key, name.as_bytes()).wait() {
                tracing::debug!(error = %e, "could not answer a ping");
            }
        })
        .background()
        .await
        .map_err(|e| anyhow!("cannot declare the ping queryable {key}: {e}"))
}

pub async fn open(options: &MeshOptions) -> Result<Session> {
    // The rules are long; the endpoints and files say which session failed.
    let summary = format!(
        "listen {:?}, connect {:?}, tls {:?}, access control {}",
        options.listen,
        options.connect,
        options.tls,
        if options.access_control.is_some() {
            "on"
        } else {
            "off"
        }
    );
    zenoh::open(config(options)?).await.map_err(|e| {
        anyhow::Error::new(NoSession {
            summary,
            zenoh: e.to_string(),
        })
    })
}

/// Zenoh could not open the session: with `connect` endpoints, most often
/// because nothing listens there (a client session needs a peer at once).
#[derive(Debug, thiserror::Error)]
#[error("cannot open a zenoh session ({summary}): {zenoh}")]
pub(crate) struct NoSession {
    summary: String,
    zenoh: String,
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    fn free_endpoint() -> String {
        let port = crate::runtime::ports::pick_free_ports(1).expect("a free port")[0];
        format!("tcp/127.0.0.1:{port}")
    }

    /// A client given every coordinator's endpoint opens on one that
    /// listens when the first is gone.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_client_given_several_endpoints_opens_on_one_that_listens() {
        let (gone, there) = (free_endpoint(), free_endpoint());
        let _server = open(&MeshOptions {
            listen: vec![there.clone()],
            ..MeshOptions::default()
        })
        .await
        .expect("the endpoint listens");
        let client = MeshOptions {
            client: true,
            connect: endpoint_list(&format!("{gone},{there}")),
            ..MeshOptions::default()
        };
        assert_eq!(client.connect, vec![gone, there]);
        tokio::time::timeout(Duration::from_secs(10), open(&client))
            .await
            .expect("the client opens at once")
            .expect("on the endpoint that listens");
    }

    /// `idmesh web` started beside a deployment may come up before the
    /// coordinator listens: its patient session waits for it, where a
    /// one-off client gives up at once.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_patient_client_waits_for_its_endpoint_to_listen() {
        let endpoint = free_endpoint();
        let impatient = MeshOptions {
            client: true,
            connect: vec![endpoint.clone()],
            ..MeshOptions::default()
        };
        let refused = tokio::time::timeout(Duration::from_secs(10), open(&impatient))
            .await
            .expect("an impatient client gives up at once");
        assert!(refused.is_err(), "nothing listens yet");

        let patient = MeshOptions {
            connect_patience: Some(Duration::from_secs(20)),
            ..impatient
        };
        let waiting = tokio::spawn(async move { open(&patient).await.map(|_| ()) });
        tokio::time::sleep(Duration::from_millis(700)).await;
        if waiting.is_finished() {
            panic!("gave up at once: {:?}", waiting.await);
        }
        let _server = open(&MeshOptions {
            listen: vec![endpoint],
            ..MeshOptions::default()
        })
        .await
        .expect("the endpoint listens");
        tokio::time::timeout(Duration::from_secs(15), waiting)
            .await
            .expect("connected soon after the endpoint listens")
            .expect("the task ran")
            .expect("the session opened");
    }
}
