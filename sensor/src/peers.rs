//! One sensor of several: fetching every other sensor's intake
//! (`P/sensor/<peer>/intake`), a task per peer. The gateway says what to
//! ask each for ([`Gateway::wanted`](crate::machine::Gateway::wanted): from
//! which entry, its own watermark, what it knows of the peer's); a task
//! asks again as soon as that changes. The peer holds a request it has
//! nothing new for until it has (or 100 ms passed), so a peer's new
//! entries arrive within a round trip of being taken, with one request
//! waiting at each peer rather than a poll. A peer that does not
//! answer is *unreachable* until it answers again: the actor then refuses
//! cuts the merge cannot place without it, naming it.

use idmesh_protocol::wire::keys::Keys;
use std::collections::BTreeSet;
use std::time::Duration;
use tokio::sync::{mpsc, watch};
use zenoh::query::{ConsolidationMode, QueryTarget};
use zenoh::Session;

/// How long after an error a peer is asked again.
pub(crate) const POLL: Duration = Duration::from_millis(5);

/// After a slice that changed nothing here (the peer held the request as
/// long as it holds one), how long before asking again.
pub(crate) const HELD_FOR: Duration = Duration::from_millis(1);

/// How long one fetch may wait for its reply.
pub(crate) const FETCH_TIMEOUT: Duration = Duration::from_secs(1);

/// What one fetch of a peer's intake got.
#[derive(Debug)]
pub(crate) enum Fetch {
    /// The slice's bytes.
    Slice(Vec<u8>),
    /// The peer answered with an error.
    Refused(String),
    /// No answer (the peer is down or cut off).
    Silent(String),
}

/// A peer's name and what fetching from it got.
pub(crate) type Fetched = (String, Fetch);

pub(crate) struct Peers {
    requests: Vec<(String, watch::Sender<Vec<u8>>)>,
    replies: mpsc::Receiver<Fetched>,
    unreachable: BTreeSet<String>,
}

impl Peers {
    /// A fetching task for each peer of `wanted` (its name and first
    /// request's bytes).
    pub(crate) fn start(session: &Session, keys: &Keys, wanted: Vec<(String, Vec<u8>)>) -> Self {
        let (tx, replies) = mpsc::channel(64);
        let mut requests = Vec::with_capacity(wanted.len());
        for (peer, request) in wanted {
            let (sender, receiver) = watch::channel(request);
            tokio::spawn(fetch(
                session.clone(),
                keys.sensor_intake(&peer),
                peer.clone(),
                receiver,
                tx.clone(),
            ));
            requests.push((peer, sender));
        }
        Peers {
            requests,
            replies,
            unreachable: BTreeSet::new(),
        }
    }

    /// What to ask each peer now (a request that did not change wakes
    /// nobody).
    pub(crate) fn ask(&self, wanted: Vec<(String, Vec<u8>)>) {
        for (peer, request) in wanted {
            if let Some((_, sender)) = self.requests.iter().find(|(p, _)| *p == peer) {
                sender.send_if_modified(|current| {
                    let changed = *current != request;
                    if changed {
                        *current = request;
                    }
                    changed
                });
            }
        }
    }

    /// The next reply of any peer.
    pub(crate) async fn reply(&mut self) -> Option<Fetched> {
        self.replies.recv().await
    }

    /// Whether `peer` answered its last fetch.
    pub(crate) fn answered(&mut self, peer: &str, answered: bool) {
        if answered {
            if self.unreachable.remove(peer) {
                tracing::info!(%peer, "peer sensor reachable again");
            }
        } else if self.unreachable.insert(peer.to_string()) {
            tracing::warn!(%peer, "peer sensor unreachable");
        }
    }

    pub(crate) fn unreachable(&self) -> &BTreeSet<String> {
        &self.unreachable
    }
}

/// Asks `peer` for its intake, again and again, until the gateway goes.
async fn fetch(
    session: Session,
    key: String,
    peer: String,
    mut requests: watch::Receiver<Vec<u8>>,
    replies: mpsc::Sender<Fetched>,
) {
    loop {
        let request = requests.borrow_and_update().clone();
        let fetched = fetch_once(&session, &key, request).await;
        let answered = matches!(fetched, Fetch::Slice(_));
        if replies.send((peer.clone(), fetched)).await.is_err() {
            return;
        }
        // A slice changes what the gateway asks next (from where, what it
        // knows): ask again once it has, at once. A peer holds a request
        // it has nothing new for, so this is no busy loop; after an error
        // (a peer down or refusing) wait a poll first.
        let wait = if answered { HELD_FOR } else { POLL };
        tokio::select! {
            changed = requests.changed() => if changed.is_err() { return },
            _ = tokio::time::sleep(wait) => {}
        }
    }
}

async fn fetch_once(session: &Session, key: &str, request: Vec<u8>) -> Fetch {
    let replies = match session
        .get(key)
        .payload(request)
        .consolidation(ConsolidationMode::None)
        .target(QueryTarget::All)
        .timeout(FETCH_TIMEOUT)
        .await
    {
        Ok(replies) => replies,
        Err(e) => return Fetch::Silent(e.to_string()),
    };
    let Ok(reply) = replies.recv_async().await else {
        return Fetch::Silent("no reply".into());
    };
    match reply.result() {
        Ok(sample) => Fetch::Slice(sample.payload().to_bytes().into_owned()),
        Err(e) => {
            let problem = String::from_utf8_lossy(&e.payload().to_bytes()).into_owned();
            // Zenoh's own reply at the timeout is no answer of the peer's.
            if problem.trim() == "Timeout" {
                Fetch::Silent(problem)
            } else {
                Fetch::Refused(problem)
            }
        }
    }
}
