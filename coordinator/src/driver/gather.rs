//! The leaders' shares at one consistent cut, and the property marginals
//! from them (identity marginals: [`crate::identity`]): the Zenoh gets.
//! What the replies mean — which are good, whether they make a complete
//! answer, how they add up — is pure ([`crate::machine`]).

pub use crate::machine::Collected;
pub(crate) use crate::machine::Gathered;
use crate::machine::{at_rest_of, check, cut_parameters, marginals_of, read_cut, Partials};
pub use crate::machine::{At, GatherError, Memory, Share};
use crate::pushed::Pushes;
use idmesh_protocol::wire::coordinator_to_leader::{LeaderStats, Partial};
use idmesh_protocol::wire::coordinator_to_sensor::{CutPlaced, SensorPositions, SensorStatus};
use idmesh_protocol::wire::keys::Keys;
use idmesh_protocol::wire::query::{LeaderPlace, PositionsAnswer, Watermark};
use idmesh_protocol::wire::Versioned;
use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Duration;
use zenoh::query::{ConsolidationMode, QueryTarget};
use zenoh::Session;

/// The marginals at a consistent cut.
pub async fn marginals(
    session: &Session,
    keys: &Keys,
    timeout: Duration,
    memory: &Memory,
    pushes: &Arc<Pushes>,
    at: At,
) -> Result<Gathered, GatherError> {
    let collected = collect(
        session,
        keys,
        timeout,
        memory,
        Some(pushes),
        at,
        Share::Sums,
    )
    .await?;
    let answer = match marginals_of(&collected, memory) {
        // Outpaced by other queries: the leaders are asked again at the
        // same cut (they keep their answers there), whole.
        Err(GatherError::StaleBase { leader, base }) => {
            tracing::debug!(leader, base, "base answer no longer kept: asking whole");
            let tag = collected.parts.first().map(|p| p.tag).filter(|&t| t != 0);
            let (parts, errors) =
                partials(session, keys, tag, Share::Sums, None, timeout, memory).await?;
            let collected = check(collected.cut, parts, errors, timeout, memory)?;
            marginals_of(&collected, memory)?
        }
        answer => answer?,
    };
    Ok(Gathered { answer })
}

/// Every leader's share at a consistent cut. Once the stream is over the
/// leaders rest at its end, and asking them where they rest is enough;
/// otherwise a fresh cut is placed, whose sums the leaders push when
/// `pushes` is given (rows are always asked for).
pub async fn collect(
    session: &Session,
    keys: &Keys,
    timeout: Duration,
    memory: &Memory,
    pushes: Option<&Arc<Pushes>>,
    at: At,
    share: Share,
) -> Result<Collected, GatherError> {
    if let (At::Latest, Some(last)) = (at, memory.finished()) {
        if let Some(collected) = at_rest(session, keys, timeout, memory, last, share).await {
            return Ok(collected);
        }
    }
    let collected = match (share, pushes) {
        (Share::Sums, Some(pushes)) => {
            pushed_at_fresh_cut(session, keys, timeout, memory, pushes, at).await?
        }
        _ => at_fresh_cut(session, keys, timeout, memory, at, share).await?,
    };
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
    let (parts, errors) = partials(session, keys, None, share, memory.base(), timeout, memory)
        .await
        .ok()?;
    at_rest_of(last, parts, errors, timeout, memory)
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
    let cut_parameters = cut_parameters(tag, at, share);
    // No cut, no answer: an error there stops the wait for the leaders.
    let (cut, (parts, errors)) = tokio::try_join!(
        place_cut(session, keys, &cut_parameters, timeout, memory),
        partials(
            session,
            keys,
            Some(tag),
            share,
            memory.base(),
            timeout,
            memory
        )
    )?;
    check(cut, parts, errors, timeout, memory)
}

/// How long a query waits for the leaders' pushed answers (counted from
/// the cut's placement) before it asks the leaders that have not pushed:
/// a push lost costs this and a round trip, a leader far behind the cut
/// is then asked and holds the question until it gets there.
const PUSH_PATIENCE: Duration = Duration::from_millis(50);

/// The sums at a fresh cut, as the leaders push them when they reach it
/// ([`crate::pushed`]); if any has not come within [`PUSH_PATIENCE`] of
/// the cut's placement, or one is bad, every leader is asked at the cut
/// (they keep their answers at recent cuts), as [`at_fresh_cut`] does.
async fn pushed_at_fresh_cut(
    session: &Session,
    keys: &Keys,
    timeout: Duration,
    memory: &Memory,
    pushes: &Arc<Pushes>,
    at: At,
) -> Result<Collected, GatherError> {
    let tag = fresh_tag();
    let mut waiting = pushes.wait_for(tag);
    let cut_parameters = cut_parameters(tag, at, Share::Sums);
    let cut = place_cut(session, keys, &cut_parameters, timeout, memory).await?;
    let mut pushed = Partials::new(Some(tag));
    let until = tokio::time::Instant::now() + PUSH_PATIENCE.min(timeout);
    // A bad push sends the query the asking way at once.
    while !pushed.complete(&cut.leaders) && !pushed.refused_any() {
        match tokio::time::timeout_at(until, waiting.rx.recv()).await {
            Ok(Some(p)) => pushed.reply(Ok(p.bytes), &p.key, memory),
            Ok(None) | Err(_) => break,
        }
    }
    drop(waiting);
    let all = pushed.complete(&cut.leaders);
    memory.note_cut(all);
    let (parts, errors) = pushed.into_parts();
    if all {
        return check(cut, parts, errors, timeout, memory);
    }
    tracing::debug!(
        tag,
        pushed = parts.len(),
        leaders = cut.leaders.len(),
        "not every leader pushed: asking"
    );
    let (parts, errors) = partials(
        session,
        keys,
        Some(tag),
        Share::Sums,
        memory.base(),
        timeout,
        memory,
    )
    .await?;
    check(cut, parts, errors, timeout, memory)
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
/// where it rests, a cut says so itself; `;base=` names the answer the
/// coordinator keeps, for a factored leader to answer with what changed
/// since), by leader, and the error replies.
#[allow(clippy::too_many_arguments)]
async fn partials(
    session: &Session,
    keys: &Keys,
    tag: Option<u64>,
    share: Share,
    base: Option<u64>,
    timeout: Duration,
    memory: &Memory,
) -> Result<(BTreeMap<String, Partial>, Vec<String>), GatherError> {
    let mut selector = match (tag, share) {
        (Some(tag), _) => format!("{}?tag={tag}", keys.every_leader_partial()),
        (None, Share::Sums) => format!("{}?quiet", keys.every_leader_partial()),
        (None, Share::Rows) => format!("{}?quiet;rows", keys.every_leader_partial()),
    };
    // A factored leader then answers with what changed since its answer
    // there (a Radon leader, or one that no longer keeps it, whole).
    if let (Some(base), Share::Sums) = (base, share) {
        selector.push_str(&format!(";base={base}"));
    }
    let replies = ask_everyone(session, selector, timeout, "query the leaders").await?;
    let mut partials = Partials::new(tag);
    while let Ok(reply) = replies.recv_async().await {
        let key = reply
            .result()
            .map_or_else(|_| String::new(), |sample| sample.key_expr().to_string());
        partials.reply(reply_bytes(&reply), &key, memory);
    }
    Ok(partials.into_parts())
}

/// A reply's bytes, or the error it carries as text.
fn reply_bytes(reply: &zenoh::query::Reply) -> Result<Vec<u8>, String> {
    match reply.result() {
        Ok(sample) => Ok(sample.payload().to_bytes().into_owned()),
        Err(e) => Err(String::from_utf8_lossy(&e.payload().to_bytes()).into_owned()),
    }
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
    // The first reply decides: one sensor places the cut. But a former
    // holder of the sensor role (cut off, still running) may answer
    // beside its successor: one at an older epoch than the role's newest
    // is passed over.
    let mut fenced = None;
    while let Ok(reply) = replies.recv_async().await {
        let key = reply
            .result()
            .map_or_else(|_| String::new(), |sample| sample.key_expr().to_string());
        let cut = read_cut(reply_bytes(&reply), &key, memory)?;
        match memory.admit_epoch(CutPlaced::WHAT, &cut.sensor, cut.epoch) {
            Ok(()) => return Ok(cut),
            Err(stale) => {
                memory.note_bad_reply("cut", &stale.to_string());
                fenced = Some(stale);
            }
        }
    }
    Err(match fenced {
        Some(stale) => {
            GatherError::Failed(format!("degraded: {stale}; no holder since placed the cut"))
        }
        None => memory.no_sensor(),
    })
}

/// Every leader's counters.
pub(crate) async fn stats(
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
pub(crate) async fn sensor_stats(
    session: &Session,
    keys: &Keys,
    timeout: Duration,
) -> Vec<SensorStatus> {
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
            if let Ok(stats) = serde_json::from_slice::<SensorStatus>(&sample.payload().to_bytes())
            {
                all.push(stats);
            }
        }
    }
    all.sort_by(|a, b| a.counters.sensor.cmp(&b.counters.sensor));
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
        return Err(memory.no_sensor());
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
            .enumerate()
            .map(|(i, (name, place))| LeaderPlace {
                name,
                at: place,
                region: at.regions.get(i).copied().flatten(),
            })
            .collect(),
        finished: at.finished,
    })
}

/// A get that every matching queryable answers on its own key (no
/// consolidation: replies from several processes must not collapse).
/// Express, so that neither the question nor its replies (which take the
/// question's QoS) wait in a Zenoh batch for company: a query is waiting.
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
        .express(true)
        .timeout(timeout)
        .await
        .map_err(|e| GatherError::Failed(format!("{what}: {e}")))
}
