//! The leader process: the [`Leader`] state machine behind Zenoh.
//!
//! One task owns the state; everything else (stream batches, transfers from
//! peers, the sensor's follow replies, the coordinator's queries) reaches it
//! through channels, so items are applied strictly one at a time. The
//! coordinator asks for a cut by its tag at the same time as it asks the
//! sensor to place it, so a query usually comes before its cut: it is held
//! until the cut arrives, or answered with an error once it has waited the
//! query timeout.
//!
//! Nothing is lost when the process dies ([`crate::journal`]): every input
//! is journaled before it is applied, a restarted leader replays its
//! journal and then fetches what it missed — batches from the sensor (a
//! replay queryable: exact, by batch number, rather than zenoh-ext's
//! advanced subscriber, whose bounded cache and sample-level recovery do
//! not know our batch numbers), transfers from its peers — and sends its
//! own transfers again. A gap in batch numbers, or a cut that is late, is
//! repaired the same way. Duplicates are dropped by the state machine.

use crate::door;
use crate::error::{MeshError, RunError};
use crate::journal::{Journal, JournalOptions, Kind, Recovered};
use crate::state::{Action, Leader};
use idmesh_protocol::wire::coordinator_to_leader::Partial;
use idmesh_protocol::wire::keys::Keys;
use idmesh_protocol::wire::leader_to_leader::{Transfer, TransfersSent, TransfersWanted};
use idmesh_protocol::wire::leader_to_sensor::{Durable, Follow, Resend, Resent};
use idmesh_protocol::wire::sensor_to_leader::Batch;
use idmesh_protocol::wire::{decode, encode, WireError, VERSION};
use std::future::Future;
use std::time::{Duration, Instant};
use tokio::sync::mpsc;
use zenoh::qos::CongestionControl;
use zenoh::query::{ConsolidationMode, Query, QueryTarget};
use zenoh::Session;

#[derive(Debug, Clone)]
pub struct LeaderConfig {
    /// The role: the leader's name in the stream and on its keys.
    pub name: String,
    /// The process running it (itself, or the one that adopted the role).
    pub host: String,
    /// The role was adopted from a process gone for good: catch up even if
    /// its journal is empty.
    pub adopted: bool,
    pub keys: Keys,
    /// The sensor gateway to ask when sets bring tracks to follow.
    pub sensor: String,
    /// How long to wait for the sensor's follow reply, and how long a query
    /// is held for a cut that has not arrived.
    pub follow_timeout: Duration,
    /// Where to keep the input journal; None = no journal (a leader that
    /// dies cannot come back).
    pub journal: Option<JournalOptions>,
    /// Write a snapshot (and start the journal again) after this many
    /// inputs; None = never (the journal grows with the stream).
    pub snapshot_every: Option<usize>,
}

/// Replies to the gets the leader makes, back in its one task.
enum Reply {
    /// The sensor's answer to a follow request (a `Followed`, as bytes).
    Followed(Result<Vec<u8>, String>),
    /// Batches asked for again.
    Resent(Result<Vec<Batch>, String>),
    /// Transfers a peer sent while this leader was down.
    Transfers(Result<Vec<Transfer>, String>),
}

/// Runs a leader until `shutdown` completes. With a journal that already
/// holds entries, the leader first replays them (rebuilding the state it
/// had when it died), then asks the sensor for every batch from the next
/// one it expects, its peers for the transfers they sent it since, and
/// sends again every transfer it sent (the receivers drop what they have).
pub async fn run(
    session: Session,
    config: LeaderConfig,
    shutdown: impl Future<Output = ()>,
) -> Result<(), RunError> {
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
    let sent = session
        .declare_queryable(keys.leader_sent(&name))
        .await
        .map_err(|e| MeshError::new("declare the sent-transfers queryable", e))?;

    let durables = session
        .declare_subscriber(keys.every_leader_durable())
        .await
        .map_err(|e| MeshError::new("declare the durable-mark subscriber", e))?;
    let (reply_tx, mut replies) = mpsc::unbounded_channel::<Reply>();
    // The token claims the role (a process coming back finds it taken);
    // queries meanwhile are told the leader is recovering.
    let _token = session
        .liveliness()
        .declare_token(keys.alive("leader", &name))
        .await
        .map_err(|e| MeshError::new("declare the liveliness token", e))?;
    let started = Instant::now();
    let (mut journal, recovered) = match &config.journal {
        Some(options) => {
            let (journal, recovered) = Journal::open(options)?;
            (Some(journal), recovered)
        }
        None => (None, Recovered::default()),
    };
    let mut leader = match &recovered.snapshot {
        Some(snapshot) => Leader::restore(snapshot)?,
        None => Leader::new(name.clone()),
    };
    leader.set_host(&config.host);
    let mut failure: Option<String> = None;
    let mut recovery: Option<Recovery> = None;
    if journal.is_some() && (!recovered.is_empty() || config.adopted) {
        for entry in &recovered.entries {
            // Only admitted inputs are journaled: the door takes them
            // again (counted if not, as when they first came).
            let Some(input) = admit(&mut leader, entry.kind, &entry.bytes, "the journal") else {
                continue;
            };
            if let Err(e) = door::apply(&mut leader, input, entry.bytes.len()) {
                failure.get_or_insert(format!("replaying the journal: {e}"));
            }
        }
        tracing::info!(leader = %name, snapshot = recovered.snapshot.is_some(),
            entries = recovered.entries.len(), position = leader.position(),
            seconds = started.elapsed().as_secs_f64(), "state recovered");
        let peers = catch_up(&session, &config, &mut leader, &reply_tx).await;
        recovery = Some(Recovery {
            since: started,
            batches: false,
            peers,
        });
    }
    tracing::info!(leader = %name, host = %config.host, "leader up");

    let mut held: Vec<Held> = Vec::new();
    let mut resending = false;
    let mut published: Option<Durable> = None;
    let mut sweep = tokio::time::interval(Duration::from_millis(250));
    tokio::pin!(shutdown);

    loop {
        // Inputs of the state machine, and where they came from: checked
        // at the door, journaled, then applied.
        let (origin, inputs): (String, Vec<(Kind, Vec<u8>)>) = tokio::select! {
            _ = &mut shutdown => break,
            sample = events.recv_async() => {
                let Ok(sample) = sample else { break };
                (sample.key_expr().to_string(), vec![(Kind::Batch, sample.payload().to_bytes().into_owned())])
            }
            sample = transfers.recv_async() => {
                let Ok(sample) = sample else { break };
                (sample.key_expr().to_string(), vec![(Kind::Transfer, sample.payload().to_bytes().into_owned())])
            }
            reply = replies.recv() => match reply {
                None => break,
                Some(Reply::Followed(Ok(bytes))) => ("the sensor's follow reply".into(), vec![(Kind::Followed, bytes)]),
                Some(Reply::Followed(Err(e))) => {
                    failure = Some(format!("follow request failed: {e}"));
                    tracing::error!(leader = %name, error = %e, "follow request failed");
                    continue;
                }
                Some(Reply::Resent(result)) => {
                    resending = false;
                    match result {
                        Ok(batches) => {
                            if let Some(r) = &mut recovery {
                                r.batches = true;
                            }
                            ("the sensor's resend reply".into(), batches.iter().map(|b| (Kind::Batch, encode(b))).collect())
                        }
                        Err(e) => {
                            tracing::warn!(leader = %name, error = %e, "resend request failed; asking again");
                            continue;
                        }
                    }
                }
                Some(Reply::Transfers(Ok(sent))) => {
                    if let Some(r) = &mut recovery {
                        r.peers = r.peers.saturating_sub(1);
                    }
                    ("a peer's sent transfers".into(), sent.iter().map(|t| (Kind::Transfer, encode(t))).collect())
                }
                Some(Reply::Transfers(Err(e))) => {
                    // A peer that is down itself sends its transfers again
                    // when it comes back.
                    if let Some(r) = &mut recovery {
                        r.peers = r.peers.saturating_sub(1);
                    }
                    tracing::warn!(leader = %name, error = %e, "a peer did not resend its transfers");
                    continue;
                }
            },
            query = partials.recv_async() => {
                let Ok(query) = query else { break };
                let recovering = recovery.as_ref().map(|r| r.since);
                let answer = partial_answer(&leader, &failure, recovering, &query);
                answer_partial(answer, query, &mut held).await;
                continue;
            }
            query = sent.recv_async() => {
                let Ok(query) = query else { break };
                let answer = sent_answer(&mut leader, &query);
                answer_sent(answer, query).await;
                continue;
            }
            sample = durables.recv_async() => {
                let Ok(sample) = sample else { break };
                match decode::<Durable>(&sample.payload().to_bytes()) {
                    Ok(mark) if mark.leader != name => {
                        leader.forget_sent(&mark.leader, mark.position);
                    }
                    Ok(_) => {}
                    Err(e) => reject(&mut leader, "a durable mark", sample.key_expr().as_str(), &e),
                }
                continue;
            }
            _ = sweep.tick() => {
                if let Some(j) = &mut journal {
                    if let Err(e) = j.sync() {
                        failure = Some(e.to_string());
                    }
                }
                // Everything journaled so far is on disk now: the others
                // may stop keeping it.
                let mark = leader.durable();
                if failure.is_none() && published.as_ref() != Some(&mark) {
                    if let Err(e) = session.put(keys.leader_durable(&name), encode(&mark)).await {
                        tracing::warn!(leader = %name, error = %e, "could not publish the durable mark");
                    }
                    published = Some(mark);
                }
                expire(&mut held, config.follow_timeout).await;
                // A gap, or a cut that is late (the batch with it, or the
                // last of the stream, may be lost): ask for the batches again.
                let late = held.iter().any(|h| h.since.elapsed() > Duration::from_millis(500));
                let unanswered = recovery.as_ref().is_some_and(|r| !r.batches);
                if !resending && (leader.missing_batches().is_some() || late || unanswered) {
                    resending = true;
                    resend(&session, &config, &leader, &reply_tx);
                }
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
        for (kind, bytes) in inputs {
            let Some(input) = admit(&mut leader, kind, &bytes, &origin) else {
                // A follow reply that was no use: the leader still waits
                // for one, so it asks again.
                if let (Kind::Followed, Some(follow)) = (kind, leader.pending_follow()) {
                    ask_to_follow(&session, &config, follow, &reply_tx);
                }
                continue;
            };
            if let Some(j) = &mut journal {
                if let Err(e) = j.append(kind, &bytes) {
                    tracing::error!(leader = %name, error = %e, "cannot journal an input");
                    failure = Some(e.to_string());
                }
            }
            let actions = match door::apply(&mut leader, input, bytes.len()) {
                Ok(actions) => actions,
                Err(e) => {
                    tracing::error!(leader = %name, error = %e, "leader cannot go on applying its stream");
                    failure = Some(e.to_string());
                    continue;
                }
            };
            act(
                &session,
                &config,
                &mut leader,
                actions,
                &mut held,
                &reply_tx,
                &mut failure,
            )
            .await;
        }
        if !resending && leader.missing_batches().is_some() {
            resending = true;
            resend(&session, &config, &leader, &reply_tx);
        }
        if recovery
            .as_ref()
            .is_some_and(|r| r.batches && r.peers == 0 && leader.missing_batches().is_none())
        {
            let seconds = recovery
                .take()
                .map_or(0.0, |r| r.since.elapsed().as_secs_f64());
            leader.note_recovered(seconds);
            tracing::info!(leader = %name, host = %config.host, seconds, position = leader.position(), "caught up");
        }
        // Every input journaled is applied: the state can replace them.
        if let (Some(j), Some(every)) = (&mut journal, config.snapshot_every) {
            if j.entries() >= every {
                let started = Instant::now();
                leader.note_snapshot();
                match j.compact(&leader.snapshot()) {
                    Ok(()) => {
                        tracing::debug!(leader = %name, seconds = started.elapsed().as_secs_f64(), "snapshot written")
                    }
                    Err(e) => {
                        tracing::error!(leader = %name, error = %e, "cannot write a snapshot");
                        failure = Some(e.to_string());
                    }
                }
            }
        }
    }
    if let Some(j) = &mut journal {
        let _ = j.sync();
    }
    tracing::info!(leader = %name, "leader stopped");
    Ok(())
}

/// The input `bytes` are, if the door lets them in; if not, the leader
/// logs who sent what and why, counts it and goes on as it was.
fn admit(leader: &mut Leader, kind: Kind, bytes: &[u8], origin: &str) -> Option<door::Input> {
    match door::admit(leader, kind, bytes) {
        Ok(input) => Some(input),
        Err(problem) => {
            let what = format!("{kind:?} of {} bytes", bytes.len());
            reject(leader, &what, origin, &problem);
            None
        }
    }
}

/// Counts and logs a message from the network the leader refused: it
/// changes nothing else.
fn reject(leader: &mut Leader, what: &str, from: &str, problem: &WireError) {
    let rejected = leader.note_rejected();
    tracing::warn!(leader = %leader.name(), from, what, %problem, rejected, "input rejected");
}

/// Carries out what the state machine asks for.
async fn act(
    session: &Session,
    config: &LeaderConfig,
    leader: &mut Leader,
    actions: Vec<Action>,
    held: &mut Vec<Held>,
    reply_tx: &mpsc::UnboundedSender<Reply>,
    failure: &mut Option<String>,
) {
    let keys = &config.keys;
    for action in actions {
        match action {
            Action::Send { to, transfer } => {
                if let Err(e) = send(session, keys, leader, to, &transfer).await {
                    *failure = Some(e);
                }
            }
            Action::Follow(follow) => ask_to_follow(session, config, &follow, reply_tx),
            Action::CutReady(partial) => {
                let ready: Vec<Held> = held.extract_if(.., |h| h.tag == partial.tag).collect();
                for h in ready {
                    reply_partial(&h.query, &partial).await;
                }
            }
        }
    }
}

/// Puts one transfer on the peer's key.
async fn send(
    session: &Session,
    keys: &Keys,
    leader: &mut Leader,
    to: u16,
    transfer: &Transfer,
) -> Result<(), String> {
    let peer = leader
        .peer(to)
        .map(str::to_owned)
        .ok_or_else(|| format!("transfer to unknown leader index {to}"))?;
    let body = encode(transfer);
    tracing::debug!(leader = %leader.name(), to = %peer, seq = transfer.seq, sets = transfer.sets.len(), "hand over sets");
    leader.note_sent(body.len());
    session
        .put(keys.leader_transfer(&peer), body)
        .congestion_control(CongestionControl::Block)
        .await
        .map_err(|e| format!("could not send sets to {peer}: {e}"))
}

/// A leader restarted (or adopted) and not yet caught up.
struct Recovery {
    since: Instant,
    /// The sensor has answered the resend of what the journal misses.
    batches: bool,
    /// Peers yet to answer the request for transfers.
    peers: usize,
}

/// After a restart: everything sent and received while down, again.
/// Returns how many peers were asked for their transfers.
async fn catch_up(
    session: &Session,
    config: &LeaderConfig,
    leader: &mut Leader,
    reply_tx: &mpsc::UnboundedSender<Reply>,
) -> usize {
    let mut asked = 0;
    for (to, transfer) in leader.all_sent().to_vec() {
        if let Err(e) = send(session, &config.keys, leader, to, &transfer).await {
            tracing::warn!(leader = %config.name, error = %e, "could not resend a transfer");
        }
    }
    resend(session, config, leader, reply_tx);
    if let Some(me) = leader.index() {
        let wanted = encode(&TransfersWanted {
            version: VERSION,
            to: me,
            after: leader.position(),
        });
        for peer in leader.leaders().iter().filter(|p| **p != config.name) {
            asked += 1;
            spawn_ask(
                session,
                config.keys.leader_sent(peer),
                wanted.clone(),
                config,
                reply_tx,
                |reply| {
                    Reply::Transfers(reply.and_then(|bytes| {
                        decode::<TransfersSent>(&bytes)
                            .map(|t| t.transfers)
                            .map_err(|e| e.to_string())
                    }))
                },
            );
        }
    }
    if let Some(follow) = leader.pending_follow() {
        ask_to_follow(session, config, follow, reply_tx);
    }
    tracing::info!(leader = %config.name, next_batch = leader.next_batch(), position = leader.position(), "catching up");
    asked
}

/// Asks the sensor to route more tracks here, with the items missed.
fn ask_to_follow(
    session: &Session,
    config: &LeaderConfig,
    follow: &Follow,
    reply_tx: &mpsc::UnboundedSender<Reply>,
) {
    let key = config.keys.sensor_follow(&config.sensor);
    spawn_ask(
        session,
        key,
        encode(follow),
        config,
        reply_tx,
        Reply::Followed,
    );
}

/// Asks the sensor for every batch from the next one this leader expects.
fn resend(
    session: &Session,
    config: &LeaderConfig,
    leader: &Leader,
    reply_tx: &mpsc::UnboundedSender<Reply>,
) {
    let request = encode(&Resend {
        version: VERSION,
        leader: config.name.clone(),
        from: leader.next_batch(),
    });
    let key = config.keys.sensor_resend(&config.sensor);
    spawn_ask(session, key, request, config, reply_tx, |reply| {
        Reply::Resent(reply.and_then(|bytes| {
            decode::<Resent>(&bytes)
                .map(|r| r.batches)
                .map_err(|e| e.to_string())
        }))
    });
}

/// Makes one get in its own task; its answer comes back to the leader's
/// task as `reply(answer)`.
fn spawn_ask(
    session: &Session,
    key: String,
    body: Vec<u8>,
    config: &LeaderConfig,
    reply_tx: &mpsc::UnboundedSender<Reply>,
    reply: fn(Result<Vec<u8>, String>) -> Reply,
) {
    let (session, tx, timeout) = (session.clone(), reply_tx.clone(), config.follow_timeout);
    tokio::spawn(async move {
        let answer = ask(&session, &key, body, timeout).await;
        let _ = tx.send(reply(answer));
    });
}

/// A peer restarted and asks for the transfers it lost.
/// A request that does not decode is answered with why and counted as
/// rejected.
fn sent_answer(leader: &mut Leader, query: &Query) -> Result<Vec<u8>, WireError> {
    let request = query
        .payload()
        .map(|p| p.to_bytes().into_owned())
        .unwrap_or_default();
    let answer = decode::<TransfersWanted>(&request).map(|wanted| {
        encode(&TransfersSent {
            version: VERSION,
            transfers: leader.sent_to(wanted.to, wanted.after),
        })
    });
    if let Err(e) = &answer {
        reject(
            leader,
            "a request for sent transfers",
            query.key_expr().as_str(),
            e,
        );
    }
    answer
}

async fn answer_sent(answer: Result<Vec<u8>, WireError>, query: Query) {
    let reply = match answer {
        Ok(body) => query.reply(query.key_expr().clone(), body).await,
        Err(e) => query.reply_err(e.to_string()).await,
    };
    if let Err(e) = reply {
        tracing::warn!(error = %e, "could not answer a request for sent transfers");
    }
}

/// One get, answered by one process: the reply's bytes, or why not.
async fn ask(
    session: &Session,
    key: &str,
    body: Vec<u8>,
    timeout: Duration,
) -> Result<Vec<u8>, String> {
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
            Ok(sample) => Ok(sample.payload().to_bytes().into_owned()),
            Err(e) => Err(String::from_utf8_lossy(&e.payload().to_bytes()).into_owned()),
        },
        Ok(Err(_)) => Err(format!("{key}: nobody answered")),
        Err(_) => Err(format!("{key}: no answer in time")),
    }
}

/// A partial-sums query waiting for its cut.
struct Held {
    tag: u64,
    since: Instant,
    query: Query,
}

/// What a partial-sums query gets.
enum Answer {
    Now(Partial),
    Refused(String),
    /// Its cut has not reached this leader yet.
    Hold(u64),
}

/// Sends `answer` (made by [`partial_answer`] beforehand: the leader is
/// not shared across an await) or holds the query for its cut.
async fn answer_partial(answer: Answer, query: Query, held: &mut Vec<Held>) {
    match answer {
        Answer::Now(partial) => reply_partial(&query, &partial).await,
        Answer::Refused(why) => {
            let _ = query.reply_err(why).await;
        }
        Answer::Hold(tag) => held.push(Held {
            tag,
            since: Instant::now(),
            query,
        }),
    }
}

fn partial_answer(
    leader: &Leader,
    failure: &Option<String>,
    recovering: Option<Instant>,
    query: &Query,
) -> Answer {
    if let Some(failure) = failure {
        return Answer::Refused(format!("leader {} failed: {failure}", leader.name()));
    }
    if let Some(since) = recovering {
        return Answer::Refused(format!(
            "degraded: leader {} is recovering its state (for {:.1} s); ask again shortly",
            leader.name(),
            since.elapsed().as_secs_f64()
        ));
    }
    if query.parameters().contains_key("quiet") {
        // `;rows`: an identity query wants the rows of the information matrix.
        return match leader.quiet(query.parameters().contains_key("rows")) {
            Some(partial) => Answer::Now(partial),
            None => Answer::Refused(format!("leader {} is not at a quiet point", leader.name())),
        };
    }
    let tag = query
        .parameters()
        .get("tag")
        .and_then(|c| c.parse::<u64>().ok());
    let Some(tag) = tag else {
        return Answer::Refused(
            "a partial-sums query needs tag=<u64> (the tag of the cut it asks for) or quiet".into(),
        );
    };
    match leader.cut(tag) {
        Some(partial) => Answer::Now(partial.clone()),
        None => Answer::Hold(tag),
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
