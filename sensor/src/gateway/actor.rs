//! The sensor process: streams a trace through the [`Router`] over Zenoh.
//!
//! One task owns the router. It publishes each leader's items as a batch on
//! the leader's own key (congestion control Block: an event is never
//! dropped), places cuts for the coordinator and answers follow requests
//! between chunks, so a cut is always a point of the same global order the
//! leaders apply. After the source is exhausted it keeps serving cuts and
//! follows until shut down, so queries keep being answered.

use super::cuts::{place, Cuts, Placed, Request};
use super::router::Router;
use idmesh_protocol::trace::Line;
use idmesh_protocol::wire::keys::Keys;
use idmesh_protocol::wire::leader_to_sensor::{Follow, Followed};
use idmesh_protocol::wire::sensor_to_leader::Batch;
use idmesh_protocol::wire::{decode, encode, VERSION};
use std::future::Future;
use std::time::{Duration, Instant};
use tracing::Instrument;
use zenoh::pubsub::Publisher;
use zenoh::qos::CongestionControl;
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

    let limit = config.limit.unwrap_or(u64::MAX) as usize;
    let lines = &lines[..lines.len().min(limit)];
    let mut stream = Stream {
        numbers: vec![0; names.len()],
        publishers,
        sensor: config.name.clone(),
        finished: lines.is_empty(),
    };
    stream.flush(&mut router).await;
    let started = Instant::now();
    let first_time = lines.iter().find_map(line_time).unwrap_or(0.0);
    let mut next = 0usize;
    let chunk = 512usize;
    let mut cuts = Cuts::default();
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
                let request = query.payload().map(|p| p.to_bytes().into_owned()).unwrap_or_default();
                match decode::<Follow>(&request).map_err(|e| e.to_string()).and_then(|f| router.follow(&f).map_err(|e| e.to_string())) {
                    Ok(items) => {
                        tracing::debug!(items = items.len(), "follow");
                        let reply = Followed { version: VERSION, items };
                        if let Err(e) = query.reply(query.key_expr().clone(), encode(&reply)).await {
                            tracing::warn!(error = %e, "could not answer a follow request");
                        }
                        stream.flush(&mut router).await;
                    }
                    Err(e) => {
                        tracing::error!(error = %e, "bad follow request");
                        let _ = query.reply_err(e).await;
                    }
                }
            }
            _ = tokio::time::sleep(wait), if due == 0 || next < lines.len() => {}
        }
    }
    Ok(())
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
    numbers: Vec<u64>,
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
            let batch = Batch {
                version: VERSION,
                sensor: self.sensor.clone(),
                number: self.numbers[i],
                through,
                events: router.events(),
                finished: self.finished,
                items: router.take(i),
            };
            self.numbers[i] += 1;
            if let Err(e) = publisher.put(encode(&batch)).await {
                tracing::error!(error = %e, "could not publish a batch");
            }
        }
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
