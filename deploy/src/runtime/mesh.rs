//! All Zenoh session setup, in one function fed by one options struct.
//!
//! Processes of a deployment are peers in a full mesh: each listens on its
//! own endpoint and connects to every other's. Peers in Zenoh 1.10 do not
//! relay for one another, so on a LAN every host must reach every other
//! host's endpoints directly (the alternative, one router with clients, puts
//! every message through one process). Multicast scouting is off: it is
//! unavailable in many networks and in CI; the topology file is the truth.
//! Clients (the query CLI, Python) connect to the coordinator's endpoint.

use anyhow::{anyhow, Result};
use zenoh::{Config, Session};

#[derive(Debug, Clone, Default)]
pub struct MeshOptions {
    /// "peer" for deployment processes, "client" for query tools.
    pub client: bool,
    pub listen: Vec<String>,
    pub connect: Vec<String>,
}

pub fn config(options: &MeshOptions) -> Result<Config> {
    let mut config = Config::default();
    let set = |config: &mut Config, key: &str, value: String| {
        config
            .insert_json5(key, &value)
            .map_err(|e| anyhow!("zenoh config {key} = {value}: {e}"))
    };
    let mode = if options.client { "client" } else { "peer" };
    set(&mut config, "mode", format!("{mode:?}"))?;
    set(
        &mut config,
        "listen/endpoints",
        serde_json::to_string(&options.listen)?,
    )?;
    set(
        &mut config,
        "connect/endpoints",
        serde_json::to_string(&options.connect)?,
    )?;
    set(&mut config, "scouting/multicast/enabled", "false".into())?;
    Ok(config)
}

/// Answers `key` at once with `name`, from Zenoh's own thread: the raw
/// round trip to this process, with none of its work in it. Health checks
/// and the bench (the floor a query is compared with) use it.
pub async fn answer_pings(session: &Session, key: String, name: String) -> Result<()> {
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
    zenoh::open(config(options)?)
        .await
        .map_err(|e| anyhow!("cannot open a zenoh session ({options:?}): {e}"))
}
