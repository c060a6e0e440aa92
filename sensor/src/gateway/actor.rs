//! The sensor process: streams a trace through the [`Router`] over Zenoh.
//!
//! One task owns the router. It publishes each leader's items as a batch on
//! the leader's own key (congestion control Block: an event is never
//! dropped), places cuts for the coordinator and answers follow requests
//! between chunks, so a cut is always a point of the same global order the
//! leaders apply. After the source is exhausted it keeps serving cuts and
//! follows until shut down, so queries keep being answered.
//!
//! Every batch sent is kept, by leader and number, so that a leader that
//! lost some (a gap in the numbers, or the time it was down and
//! restarting) gets them again on `P/sensor/<name>/resend`, until the
//! leader publishes a durable mark past it ([`BatchLog`]); items every
//! leader has passed leave the router's log the same way. The logs live in
//! memory: the sensor is the source of truth of the stream, not a process
//! this design lets die. [`Faults`] drops or doubles batches on purpose,
//! for the tests that show neither matters.

use super::batch_log::BatchLog;
use super::cuts::{place, Cuts, Placed, Request};
use super::router::Router;
use idmesh_protocol::trace::Line;
use idmesh_protocol::wire::coordinator_to_sensor::SensorStats;
use idmesh_protocol::wire::keys::Keys;
use idmesh_protocol::wire::leader_to_sensor::{Durable, Follow, Followed, Resend, Resent};
use idmesh_protocol::wire::sensor_to_leader::Batch;
use idmesh_protocol::wire::{decode, encode, VERSION};
use std::future::Future;
use std::time::{Duration, Instant};
use tracing::Instrument;
use zenoh::pubsub::Publisher;
use zenoh::qos::CongestionControl;
use zenoh::query::Query;
use zenoh::Session;

#[derive(Debug, Clone)]
pub struct GatewayConfig {
    pub name: String,
    pub keys: Keys,
    /// Events per second; None = as fast as the leaders take them.
    pub rate: Option<f64>,
    /// Pace by the trace's own times instead (`rate` then scales them).
    pub realtime: bool,
    /// Stop after this many events.
    pub limit: Option<u64>,
    /// How long to wait for every leader to be up.
    pub wait_for_leaders: Duration,
    pub faults: Faults,
}

/// Faults injected on purpose (tests): the network losing or doubling
/// event batches.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Faults {
    /// Every batch is published twice.
    pub duplicate: bool,
    /// Every n-th batch to each leader is not published at all (it stays
    /// in the log, for the leader to ask for again).
    pub drop_every: Option<u64>,
}

#[derive(Debug, thiserror::Error)]
pub enum GatewayError {
    #[error("zenoh: {what}: {message}")]
    Mesh { what: &'static str, message: String },
    #[error("leaders {missing:?} did not come up within {waited:?}")]
    LeadersMissing {
        missing: Vec<String>,
        waited: Duration,
    },
}

fn mesh(what: &'static str) -> impl FnOnce(zenoh::Error) -> GatewayError {
    move |e| GatewayError::Mesh {
        what,
        message: e.to_string(),
    }
}

/// How many of `lines` the stream sends, and how many events they hold:
/// `limit` counts events, as watermarks and `?events=N` do, not lines
/// (truth lines carry no event).
fn stream_length(lines: &[Line], limit: Option<u64>) -> (usize, u64) {
    let mut events = 0u64;
    for (i, line) in lines.iter().enumerate() {
        if !matches!(line, Line::Truth(_)) {
            if limit.is_some_and(|limit| events == limit) {
                return (i, events);
            }
            events += 1;
        }
    }
    (lines.len(), events)
}

/// Streams `lines` (the events of a trace, header excluded) until done,
/// then serves queries until `shutdown`.
pub async fn run(
    session: Session,
    config: GatewayConfig,
    mut router: Router,
    lines: Vec<Line>,
    shutdown: impl Future<Output = ()>,
) -> Result<(), GatewayError> {
    let keys = &config.keys;
    let cut_requests = session
        .declare_queryable(keys.sensor_cut(&config.name))
        .await
        .map_err(mesh("declare the cut queryable"))?;
    let follows = session
        .declare_queryable(keys.sensor_follow(&config.name))
        .await
        .map_err(mesh("declare the follow queryable"))?;
    let resends = session
        .declare_queryable(keys.sensor_resend(&config.name))
        .await
        .map_err(mesh("declare the resend queryable"))?;
    let durables = session
        .declare_subscriber(keys.every_leader_durable())
        .await
        .map_err(mesh("declare the durable-mark subscriber"))?;
    let stats = session
        .declare_queryable(keys.sensor_stats(&config.name))
        .await
        .map_err(mesh("declare the stats queryable"))?;
    // Follow and resend requests refused: a bad one is answered with why
    // and changes nothing.
    let mut counters = SensorStats {
        sensor: config.name.clone(),
        rejected: 0,
    };
    let _token = session
        .liveliness()
        .declare_token(keys.alive("sensor", &config.name))
        .await
        .map_err(mesh("declare the liveliness token"))?;
    let names = router.begin().leaders.clone();
    let mut publishers = Vec::with_capacity(names.len());
    for name in &names {
        publishers.push(
            session
                .declare_publisher(keys.leader_events(name))
                .congestion_control(CongestionControl::Block)
                .await
                .map_err(mesh("declare an event publisher"))?,
        );
    }
    wait_for_leaders(&session, keys, &names, config.wait_for_leaders).await?;
    tracing::info!(sensor = %config.name, leaders = names.len(), events = lines.len(), "streaming");

    let (length, end) = stream_length(&lines, config.limit);
    let lines = &lines[..length];
    let mut stream = Stream {
        sent: (0..names.len()).map(|_| BatchLog::default()).collect(),
        durable: vec![None; names.len()],
        names: names.clone(),
        faults: config.faults,
        publishers,
        sensor: config.name.clone(),
        finished: lines.is_empty(),
    };
    stream.flush(&mut router).await;
    let started = Instant::now();
    let first_time = lines.iter().find_map(line_time).unwrap_or(0.0);
    let mut next = 0usize;
    let chunk = 512usize;
    let mut cuts = Cuts::ending_at(end);
    tokio::pin!(shutdown);
    loop {
        // How many lines are due now, and when the next one is.
        let (due, wait) = if stream.finished {
            (0, Duration::from_secs(3600))
        } else {
            due_lines(&config, lines, next, started, first_time, chunk)
        };
        if due > 0 {
            let mut placed = Vec::new();
            for line in &lines[next..next + due] {
                router.line(line);
                cuts.reached(&mut router, &config.name, &mut placed);
            }
            next += due;
            stream.finished = next >= lines.len();
            stream
                .flush(&mut router)
                .instrument(tracing::debug_span!(
                    "chunk",
                    from = next - due,
                    lines = due
                ))
                .await;
            for p in placed {
                reply_placed(p).await;
            }
            if stream.finished {
                tracing::info!(sensor = %config.name, events = router.events(), seconds = started.elapsed().as_secs_f64(), "source exhausted");
                for (query, reason) in cuts.refuse_all(&router) {
                    let _ = query.reply_err(reason).await;
                }
            }
            // Let queries in between chunks.
            tokio::task::yield_now().await;
        }
        tokio::select! {
            biased;
            _ = &mut shutdown => break,
            query = cut_requests.recv_async() => {
                let Ok(query) = query else { break };
                match cuts.request(query, &router, stream.finished) {
                    Request::Now { wanted, query } => {
                        let p = place(&mut router, &config.name, wanted, query, stream.finished);
                        stream.flush(&mut router).await;
                        reply_placed(p).await;
                    }
                    Request::Scheduled => {}
                    Request::Refused { query, reason } => {
                        let _ = query.reply_err(reason).await;
                    }
                }
            }
            query = follows.recv_async() => {
                let Ok(query) = query else { break };
                let answer = decode::<Follow>(&payload(&query))
                    .map_err(|e| e.to_string())
                    .and_then(|f| router.follow(&f).map_err(|e| e.to_string()))
                    .map(|items| Followed { version: VERSION, items });
                let followed = answer.is_ok();
                reply_to(&query, answer, "follow", &mut counters).await;
                if followed {
                    stream.flush(&mut router).await;
                }
            }
            sample = durables.recv_async() => {
                let Ok(sample) = sample else { break };
                match decode::<Durable>(&sample.payload().to_bytes()) {
                    Ok(mark) => stream.forget(&mark, &mut router),
                    Err(e) => {
                        counters.rejected += 1;
                        tracing::warn!(from = %sample.key_expr(), problem = %e,
                            rejected = counters.rejected, "durable mark rejected");
                    }
                }
            }
            query = resends.recv_async() => {
                let Ok(query) = query else { break };
                let answer = decode::<Resend>(&payload(&query))
                    .map_err(|e| e.to_string())
                    .and_then(|r| stream.resend(&r))
                    .map(|batches| Resent { version: VERSION, batches });
                reply_to(&query, answer, "resend", &mut counters).await;
            }
            query = stats.recv_async() => {
                let Ok(query) = query else { break };
                let body = serde_json::to_vec(&counters).unwrap_or_default();
                if let Err(e) = query.reply(query.key_expr().clone(), body)
                    .encoding(zenoh::bytes::Encoding::APPLICATION_JSON).await
                {
                    tracing::warn!(error = %e, "could not answer a stats query");
                }
            }
            _ = tokio::time::sleep(wait), if due == 0 || next < lines.len() => {}
        }
    }
    Ok(())
}

/// The postcard request a get carries.
fn payload(query: &Query) -> Vec<u8> {
    query
        .payload()
        .map(|p| p.to_bytes().into_owned())
        .unwrap_or_default()
}

/// Answers a `what` request with its reply, or with why there is none
/// (counted in `stats`).
async fn reply_to<R: serde::Serialize>(
    query: &Query,
    answer: Result<R, String>,
    what: &str,
    stats: &mut SensorStats,
) {
    match answer {
        Ok(reply) => {
            tracing::debug!(what, "answered");
            if let Err(e) = query.reply(query.key_expr().clone(), encode(&reply)).await {
                tracing::warn!(what, error = %e, "could not answer a request");
            }
        }
        Err(e) => {
            stats.rejected += 1;
            tracing::warn!(what, key = %query.key_expr(), error = %e, rejected = stats.rejected, "bad request rejected");
            let _ = query.reply_err(e).await;
        }
    }
}

async fn reply_placed(placed: Placed) {
    let query = placed.query;
    if let Err(e) = query
        .reply(query.key_expr().clone(), encode(&placed.answer))
        .await
    {
        tracing::warn!(error = %e, "could not answer a cut");
    }
}

struct Stream {
    /// The batches sent to each leader that it may still ask for.
    sent: Vec<BatchLog>,
    /// The last durable position each leader published.
    durable: Vec<Option<u64>>,
    names: Vec<String>,
    faults: Faults,
    publishers: Vec<Publisher<'static>>,
    sensor: String,
    /// The whole source has been read.
    finished: bool,
}

impl Stream {
    /// Sends every leader its queued items, or just how far the stream got.
    async fn flush(&mut self, router: &mut Router) {
        let through = router.seq();
        for (i, publisher) in self.publishers.iter().enumerate() {
            let number = self.sent[i].next_number();
            let batch = Batch {
                version: VERSION,
                sensor: self.sensor.clone(),
                number,
                through,
                events: router.events(),
                finished: self.finished,
                items: router.take(i),
            };
            let body = encode(&batch);
            self.sent[i].push(batch);
            let dropped = self
                .faults
                .drop_every
                .is_some_and(|n| n > 0 && number % n == n - 1);
            if dropped {
                tracing::debug!(leader = i, number, "fault: batch not published");
                continue;
            }
            for _ in 0..if self.faults.duplicate { 2 } else { 1 } {
                if let Err(e) = publisher.put(body.clone()).await {
                    tracing::error!(error = %e, "could not publish a batch");
                }
            }
        }
    }

    /// The batches leader `request.leader` asks for again.
    fn resend(&self, request: &Resend) -> Result<Vec<Batch>, String> {
        let sent = self
            .names
            .iter()
            .position(|n| *n == request.leader)
            .map(|i| &self.sent[i])
            .ok_or_else(|| {
                format!(
                    "resend request from {:?}, which is not a leader of this stream",
                    request.leader
                )
            })?;
        sent.from(&request.leader, request.from)
    }

    /// A leader's state is safe through `mark`: drop its batches below it,
    /// and the items every leader has passed.
    fn forget(&mut self, mark: &Durable, router: &mut Router) {
        let Some(i) = self.names.iter().position(|n| *n == mark.leader) else {
            tracing::warn!(leader = %mark.leader, "durable mark from a leader not of this stream");
            return;
        };
        let batches = self.sent[i].forget(mark);
        self.durable[i] = Some(self.durable[i].unwrap_or(0).max(mark.position));
        let passed = self.durable.iter().copied().min().flatten();
        let items = passed.map_or(0, |seq| router.forget(seq));
        tracing::trace!(leader = %mark.leader, batches, items, kept = self.sent[i].len(),
            logged = router.logged(), "forgot what is safe");
    }
}

fn line_time(line: &Line) -> Option<f64> {
    match line {
        Line::Mix(m) => Some(m.time),
        Line::Observe(o) => Some(o.time),
        Line::Move(m) => Some(m.time),
        Line::Identify(i) => Some(i.time),
        Line::Truth(t) => Some(t.time),
        Line::Header(_) => None,
    }
}

fn due_lines(
    config: &GatewayConfig,
    lines: &[Line],
    next: usize,
    started: Instant,
    first_time: f64,
    chunk: usize,
) -> (usize, Duration) {
    let elapsed = started.elapsed().as_secs_f64();
    let rest = lines.len() - next;
    if config.realtime {
        let speed = config.rate.unwrap_or(1.0);
        let mut due = 0;
        while due < rest.min(chunk) {
            let t = line_time(&lines[next + due]).unwrap_or(first_time) - first_time;
            if t / speed > elapsed {
                let wait = (t / speed - elapsed).max(0.0);
                return (due, Duration::from_secs_f64(wait.min(0.05)));
            }
            due += 1;
        }
        return (due, Duration::ZERO);
    }
    match config.rate {
        None => (rest.min(chunk), Duration::ZERO),
        Some(rate) => {
            let allowed = (elapsed * rate) as usize;
            let due = allowed.saturating_sub(next).min(rest).min(chunk);
            (due, Duration::from_millis(if due == 0 { 2 } else { 0 }))
        }
    }
}

async fn wait_for_leaders(
    session: &Session,
    keys: &Keys,
    names: &[String],
    patience: Duration,
) -> Result<(), GatewayError> {
    let started = Instant::now();
    loop {
        let mut up = Vec::new();
        if let Ok(replies) = session
            .liveliness()
            .get(keys.alive_role("leader"))
            .timeout(Duration::from_secs(1))
            .await
        {
            while let Ok(reply) = replies.recv_async().await {
                if let Ok(sample) = reply.result() {
                    if let Some(name) = Keys::chunk(sample.key_expr().as_str(), 0) {
                        up.push(name.to_string());
                    }
                }
            }
        }
        let missing: Vec<String> = names.iter().filter(|n| !up.contains(n)).cloned().collect();
        if missing.is_empty() {
            return Ok(());
        }
        if started.elapsed() > patience {
            return Err(GatewayError::LeadersMissing {
                missing,
                waited: patience,
            });
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

#[cfg(test)]
mod tests {
    use super::stream_length;
    use idmesh_protocol::trace::{Line, Mix, Truth};

    fn mix() -> Line {
        Line::Mix(Mix {
            time: 0.0,
            a: 0,
            b: 1,
            swap: 0.5,
        })
    }

    fn truth() -> Line {
        Line::Truth(Truth {
            time: 0.0,
            red: Some(vec![0]),
            identity: None,
        })
    }

    #[test]
    fn an_event_limit_counts_events_not_truth_lines() {
        let lines = [mix(), truth(), mix(), truth(), mix(), mix()];
        assert_eq!(stream_length(&lines, Some(3)), (5, 3));
        assert_eq!(stream_length(&lines, Some(4)), (6, 4));
        assert_eq!(stream_length(&lines, Some(9)), (6, 4));
        assert_eq!(stream_length(&lines, None), (6, 4));
        assert_eq!(stream_length(&lines, Some(0)), (0, 0));
    }
}
