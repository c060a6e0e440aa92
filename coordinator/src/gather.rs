//! The leaders' shares at one consistent cut, and the property marginals
//! from them (identity marginals: [`crate::identity`]).

use idmesh_belief::predict_red;
use idmesh_leader::combine;
use idmesh_protocol::wire::bounds::Bounds;
use idmesh_protocol::wire::coordinator_to_leader::{LeaderStats, Partial};
use idmesh_protocol::wire::coordinator_to_sensor::{CutPlaced, SensorPositions, SensorStats};
use idmesh_protocol::wire::decode;
use idmesh_protocol::wire::keys::Keys;
use idmesh_protocol::wire::query::{
    CoordinatorStats, LeaderPlace, MarginalsAnswer, PositionsAnswer, Watermark,
};
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;
use std::time::Duration;
use zenoh::query::{ConsolidationMode, QueryTarget};
use zenoh::Session;

#[derive(Debug, thiserror::Error)]
pub enum GatherError {
    #[error("no sensor gateway answered: the stream has no source yet")]
    NoSensor,
    #[error("no leader is listed by the sensor")]
    NoLeaders,
    #[error("degraded: leaders {missing:?} did not answer (waited up to {timeout:?}); no partial answer is given")]
    Missing {
        missing: Vec<String>,
        timeout: Duration,
    },
    #[error("{0}")]
    Failed(String),
    /// Leaders answered, but not all with their share at the cut (one is
    /// recovering, waits for a peer that is down, …).
    #[error("degraded: {0}; no partial answer is given")]
    Refused(String),
    #[error("the belief has no mass at this cut: the observations contradict each other")]
    Degenerate,
}

/// What a marginals query found.
#[derive(Debug, Clone)]
pub struct Gathered {
    pub cut: CutPlaced,
    pub answer: MarginalsAnswer,
}

/// Every leader's share at one cut: all of them, at the same seq.
#[derive(Debug, Clone)]
pub struct Collected {
    pub cut: CutPlaced,
    pub parts: Vec<Partial>,
}

impl Collected {
    /// What the answer includes: per sensor, its events.
    pub fn watermark(&self) -> Watermark {
        let mut watermark = Watermark::new();
        watermark.insert(self.cut.sensor.clone(), self.cut.events);
        watermark
    }
}

/// What the leaders add to their partial sums.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Share {
    /// The partial sums of the property belief only.
    Sums,
    /// Their rows of the information matrix too (identity queries).
    Rows,
}

/// What the coordinator keeps between queries: the last cut of a stream
/// that was over, and its counts of bad input. Nothing is pushed to it; it
/// only remembers what it asked.
#[derive(Debug, Default)]
pub struct Memory {
    finished: Mutex<Option<CutPlaced>>,
    rejected: AtomicU64,
    bad_replies: AtomicU64,
    degraded: AtomicU64,
}

impl Memory {
    /// Counts a query refused for its parameters.
    pub fn note_rejected(&self) {
        self.rejected.fetch_add(1, Ordering::Relaxed);
    }

    /// Counts a reply from another process that was no good.
    fn note_bad_reply(&self, what: &str, problem: &str) {
        let n = self.bad_replies.fetch_add(1, Ordering::Relaxed) + 1;
        tracing::warn!(what, problem, bad_replies = n, "bad reply");
    }

    /// Counts a query answered `degraded: …` (a leader missing or not
    /// at the cut).
    pub fn note_degraded(&self) {
        self.degraded.fetch_add(1, Ordering::Relaxed);
    }

    pub fn stats(&self) -> CoordinatorStats {
        CoordinatorStats {
            rejected: self.rejected.load(Ordering::Relaxed),
            bad_replies: self.bad_replies.load(Ordering::Relaxed),
            degraded: self.degraded.load(Ordering::Relaxed),
        }
    }

    fn finished(&self) -> Option<CutPlaced> {
        self.finished.lock().ok().and_then(|c| c.clone())
    }

    fn remember(&self, cut: &CutPlaced) {
        if let Ok(mut slot) = self.finished.lock() {
            *slot = cut.finished.then(|| cut.clone());
        }
    }
}

/// Where in the stream an answer is wanted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum At {
    /// As far as the stream has got.
    Latest,
    /// Right after the stream's n-th event (which may not have come yet:
    /// the answer waits for it, up to the timeout).
    Events(u64),
}

/// The marginals at a consistent cut.
pub async fn marginals(
    session: &Session,
    keys: &Keys,
    timeout: Duration,
    memory: &Memory,
    at: At,
) -> Result<Gathered, GatherError> {
    let collected = collect(session, keys, timeout, memory, at, Share::Sums).await?;
    let sums = combine(&collected.parts);
    let cut = &collected.cut;
    let p_red = sums
        .marginals(cut.tracks as usize)
        .map_err(|_| GatherError::Degenerate)?;
    let predicted_red = predict_red(&p_red, cut.red.map(|k| k as usize));
    let answer = MarginalsAnswer {
        watermark: collected.watermark(),
        tracks: cut.tracks,
        red: cut.red,
        p_red,
        predicted_red,
        leaders: collected.parts.len() as u32,
        coefficients: sums.coefficients,
        finished: cut.finished,
    };
    Ok(Gathered {
        cut: collected.cut,
        answer,
    })
}

/// Every leader's share at a consistent cut. Once the stream is over the
/// leaders rest at its end, and asking them where they rest is enough;
/// otherwise a fresh cut is placed.
pub async fn collect(
    session: &Session,
    keys: &Keys,
    timeout: Duration,
    memory: &Memory,
    at: At,
    share: Share,
) -> Result<Collected, GatherError> {
    if let (At::Latest, Some(last)) = (at, memory.finished()) {
        if let Some(collected) = at_rest(session, keys, timeout, memory, last, share).await {
            return Ok(collected);
        }
    }
    let collected = at_fresh_cut(session, keys, timeout, memory, at, share).await?;
    memory.remember(&collected.cut);
    Ok(collected)
}

/// The answer where the leaders rest, if every leader of `last` rests at
/// the same seq at the end of the stream (they then hold the final belief:
/// every set sent has been received). None sends the query the long way.
async fn at_rest(
    session: &Session,
    keys: &Keys,
    timeout: Duration,
    memory: &Memory,
    last: CutPlaced,
    share: Share,
) -> Option<Collected> {
    let (parts, errors) = partials(session, keys, None, share, timeout, memory)
        .await
        .ok()?;
    let first = parts.values().next()?;
    let agreed = errors.is_empty()
        && parts.values().all(|p| p.finished && p.cut == first.cut)
        && last.leaders.iter().all(|l| parts.contains_key(l));
    if !agreed {
        return None;
    }
    let cut = CutPlaced {
        seq: first.cut,
        events: first.events,
        ..last
    };
    check(cut, parts, Vec::new(), timeout, memory).ok()
}

/// The marginals at a fresh cut. The sensor is asked to place the cut and
/// the leaders to answer at it in the same breath: each leader holds the
/// query until the cut's tag reaches it in its stream, so a query costs one
/// round trip to the slowest of them rather than two in a row.
async fn at_fresh_cut(
    session: &Session,
    keys: &Keys,
    timeout: Duration,
    memory: &Memory,
    at: At,
    share: Share,
) -> Result<Collected, GatherError> {
    let tag = fresh_tag();
    let mut cut_parameters = match at {
        At::Latest => format!("tag={tag}"),
        At::Events(n) => format!("tag={tag};events={n}"),
    };
    if share == Share::Rows {
        cut_parameters.push_str(";rows");
    }
    // No cut, no answer: an error there stops the wait for the leaders.
    let (cut, (parts, errors)) = tokio::try_join!(
        place_cut(session, keys, &cut_parameters, timeout, memory),
        partials(session, keys, Some(tag), share, timeout, memory)
    )?;
    check(cut, parts, errors, timeout, memory)
}

/// The leaders' shares at `cut` if every leader answered there, or who is
/// missing or what went wrong: never a partial answer dressed as complete.
fn check(
    cut: CutPlaced,
    parts: BTreeMap<String, Partial>,
    mut errors: Vec<String>,
    timeout: Duration,
    memory: &Memory,
) -> Result<Collected, GatherError> {
    if cut.leaders.is_empty() {
        return Err(GatherError::NoLeaders);
    }
    // Sums of tracks or rows beyond the cut's field would be dropped or
    // fail later without saying whose they were.
    let bounds = Bounds {
        tracks: cut.tracks,
        leaders: cut.leaders.len(),
        identities: cut.identities,
    };
    for p in parts.values() {
        if let Err(e) = bounds.check_partial(p) {
            let problem = format!("{}: {e}", p.leader);
            memory.note_bad_reply("partial sums", &problem);
            errors.push(problem);
        }
    }
    for p in parts.values().filter(|p| p.cut != cut.seq) {
        errors.push(format!(
            "{} answered at seq {} for a cut at {}",
            p.leader, p.cut, cut.seq
        ));
    }
    if !errors.is_empty() {
        return Err(GatherError::Refused(errors.join("; ")));
    }
    let missing: Vec<String> = cut
        .leaders
        .iter()
        .filter(|l| !parts.contains_key(*l))
        .cloned()
        .collect();
    if !missing.is_empty() {
        return Err(GatherError::Missing { missing, timeout });
    }
    Ok(Collected {
        cut,
        parts: parts.into_values().collect(),
    })
}

/// A tag no other query of any coordinator is likely to use: the std
/// hasher's random keys over a per-process counter.
fn fresh_tag() -> u64 {
    use std::hash::{BuildHasher, Hasher};
    use std::sync::atomic::{AtomicU64, Ordering};
    static NEXT: AtomicU64 = AtomicU64::new(0);
    let mut hasher = std::collections::hash_map::RandomState::new().build_hasher();
    hasher.write_u64(NEXT.fetch_add(1, Ordering::Relaxed));
    hasher.finish()
}

/// Every leader's partial sums (`?tag=<tag>` at the cut with that tag,
/// `?quiet` where it rests when `tag` is None; `;rows` adds the rows
/// where it rests, a cut says so itself), by leader, and the error replies.
async fn partials(
    session: &Session,
    keys: &Keys,
    tag: Option<u64>,
    share: Share,
    timeout: Duration,
    memory: &Memory,
) -> Result<(BTreeMap<String, Partial>, Vec<String>), GatherError> {
    let selector = match (tag, share) {
        (Some(tag), _) => format!("{}?tag={tag}", keys.every_leader_partial()),
        (None, Share::Sums) => format!("{}?quiet", keys.every_leader_partial()),
        (None, Share::Rows) => format!("{}?quiet;rows", keys.every_leader_partial()),
    };
    let replies = ask_everyone(session, selector, timeout, "query the leaders").await?;
    let mut parts = BTreeMap::new();
    let mut errors = Vec::new();
    while let Ok(reply) = replies.recv_async().await {
        match reply.result() {
            Ok(sample) => match decode::<Partial>(&sample.payload().to_bytes()) {
                Ok(p) if tag.is_none_or(|t| t == p.tag) => {
                    parts.insert(p.leader.clone(), p);
                }
                Ok(p) => errors.push(format!("{} answered tag {} for {tag:?}", p.leader, p.tag)),
                Err(e) => {
                    let problem = format!("{}: {e}", sample.key_expr());
                    memory.note_bad_reply("partial sums", &problem);
                    errors.push(problem);
                }
            },
            Err(e) => errors.push(String::from_utf8_lossy(&e.payload().to_bytes()).into_owned()),
        }
    }
    Ok((parts, errors))
}

async fn place_cut(
    session: &Session,
    keys: &Keys,
    parameters: &str,
    timeout: Duration,
    memory: &Memory,
) -> Result<CutPlaced, GatherError> {
    let selector = format!("{}?{parameters}", keys.every_sensor_cut());
    let replies = ask_everyone(session, selector, timeout, "ask for a cut").await?;
    // The first reply decides: one sensor places the cut.
    let Ok(reply) = replies.recv_async().await else {
        return Err(GatherError::NoSensor);
    };
    match reply.result() {
        Ok(sample) => decode::<CutPlaced>(&sample.payload().to_bytes()).map_err(|e| {
            let problem = format!("{}: {e}", sample.key_expr());
            memory.note_bad_reply("cut", &problem);
            GatherError::Failed(problem)
        }),
        Err(e) => Err(GatherError::Failed(format!(
            "the sensor placed no cut: {}",
            String::from_utf8_lossy(&e.payload().to_bytes())
        ))),
    }
}

/// Every leader's counters.
pub async fn stats(
    session: &Session,
    keys: &Keys,
    timeout: Duration,
) -> Result<Vec<LeaderStats>, GatherError> {
    let replies = ask_everyone(
        session,
        keys.every_leader_stats(),
        timeout,
        "query the leaders",
    )
    .await?;
    let mut all = Vec::new();
    while let Ok(reply) = replies.recv_async().await {
        if let Ok(sample) = reply.result() {
            if let Ok(stats) = serde_json::from_slice::<LeaderStats>(&sample.payload().to_bytes()) {
                all.push(stats);
            }
        }
    }
    if all.is_empty() {
        return Err(GatherError::NoLeaders);
    }
    all.sort_by(|a, b| a.leader.cmp(&b.leader));
    Ok(all)
}

/// Every sensor gateway's counters (none when no gateway answers: the
/// leaders' counters are still worth having).
pub async fn sensor_stats(session: &Session, keys: &Keys, timeout: Duration) -> Vec<SensorStats> {
    let Ok(replies) = ask_everyone(
        session,
        keys.every_sensor_stats(),
        timeout,
        "query the sensors",
    )
    .await
    else {
        return Vec::new();
    };
    let mut all = Vec::new();
    while let Ok(reply) = replies.recv_async().await {
        if let Ok(sample) = reply.result() {
            if let Ok(stats) = serde_json::from_slice::<SensorStats>(&sample.payload().to_bytes()) {
                all.push(stats);
            }
        }
    }
    all.sort_by(|a, b| a.sensor.cmp(&b.sensor));
    all
}

/// Where every track was last seen and who surveils it, from the sensor
/// gateway (only it sees `move` lines), at the point its router has
/// reached; checked before it is passed on.
pub async fn positions(
    session: &Session,
    keys: &Keys,
    timeout: Duration,
    memory: &Memory,
) -> Result<PositionsAnswer, GatherError> {
    let replies = ask_everyone(
        session,
        keys.every_sensor_positions(),
        timeout,
        "ask the sensor for positions",
    )
    .await?;
    let Ok(reply) = replies.recv_async().await else {
        return Err(GatherError::NoSensor);
    };
    let sample = reply.result().map_err(|e| {
        GatherError::Failed(format!(
            "the sensor gave no positions: {}",
            String::from_utf8_lossy(&e.payload().to_bytes())
        ))
    })?;
    let at = serde_json::from_slice::<SensorPositions>(&sample.payload().to_bytes())
        .map_err(|e| e.to_string())
        .and_then(|p| p.check().map(|()| p))
        .map_err(|problem| {
            let problem = format!("{}: {problem}", sample.key_expr());
            memory.note_bad_reply("positions", &problem);
            GatherError::Failed(problem)
        })?;
    let mut watermark = Watermark::new();
    watermark.insert(at.sensor, at.events);
    Ok(PositionsAnswer {
        watermark,
        tracks: at.positions.len() as u32,
        positions: at.positions,
        owners: at.owners,
        leaders: at
            .leaders
            .into_iter()
            .zip(at.places)
            .map(|(name, at)| LeaderPlace { name, at })
            .collect(),
        finished: at.finished,
    })
}

/// A get that every matching queryable answers on its own key (no
/// consolidation: replies from several processes must not collapse).
async fn ask_everyone(
    session: &Session,
    selector: String,
    timeout: Duration,
    what: &str,
) -> Result<zenoh::handlers::FifoChannelHandler<zenoh::query::Reply>, GatherError> {
    session
        .get(selector)
        .consolidation(ConsolidationMode::None)
        .target(QueryTarget::All)
        .timeout(timeout)
        .await
        .map_err(|e| GatherError::Failed(format!("{what}: {e}")))
}
