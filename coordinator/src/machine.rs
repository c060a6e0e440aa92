//! The coordinator's gathering and combining as pure functions: what the
//! replies of the sensor and the leaders to one query mean, whether they
//! make a complete answer at one consistent cut, and the property
//! marginals they add up to. No I/O: the Zenoh gets are in
//! [`crate::driver::gather`], and the deterministic network simulator
//! (`tests/src/sim`) feeds these the replies of simulated processes.

use bytes::Bytes;
use idmesh_belief::predict_red;
use idmesh_belief::BeliefError;
use idmesh_belief::Field;
use idmesh_belief::{CountPart, CouplingTree};
use idmesh_placement::combine;
use idmesh_protocol::wire::bounds::Bounds;
use idmesh_protocol::wire::coordinator_to_leader::Partial;
use idmesh_protocol::wire::coordinator_to_sensor::CutPlaced;
use idmesh_protocol::wire::epoch::{Fence, Stale};
use idmesh_protocol::wire::identity::WireTree;
use idmesh_protocol::wire::leader_to_leader::WireRow;
use idmesh_protocol::wire::query::{CoordinatorStats, MarginalsAnswer, Watermark};
use idmesh_protocol::wire::{decode, Versioned};
use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

#[derive(Debug, thiserror::Error)]
pub enum GatherError {
    #[error("no sensor gateway answered: the stream has no source yet")]
    NoSensor,
    /// No sensor answered, and these had placed cuts before: they are
    /// down or cut off, and an answer without their events would be
    /// numbers without them.
    #[error(
        "degraded: sensors {0:?} did not answer (down, or cut off); no partial answer is given"
    )]
    SensorsDown(Vec<String>),
    #[error("no leader is listed by the sensor")]
    NoLeaders,
    #[error("degraded: leaders {missing:?} did not answer (waited up to {timeout:?}){}; no partial answer is given", others.iter().map(|o| format!("; {o}")).collect::<String>())]
    Missing {
        missing: Vec<String>,
        timeout: Duration,
        /// What the leaders that did answer said instead of their sums.
        others: Vec<String>,
    },
    #[error("{0}")]
    Failed(String),
    /// Leaders answered, but not all with their share at the cut (one is
    /// recovering, waits for a peer that is down, …).
    #[error("degraded: {0}; no partial answer is given")]
    Refused(String),
    #[error("the belief has no mass at this cut: the observations contradict each other")]
    Degenerate,
    /// A leader told its answer as a change to one the coordinator no
    /// longer keeps (many queries at once): asked again whole.
    #[error("leader {leader} answered as a change to its answer at the cut tagged {base}, which the coordinator no longer keeps; ask again")]
    StaleBase { leader: String, base: u64 },
}

/// How many factored answers the coordinator keeps for leaders to answer
/// against (`;base=`): one is named per query, and the others serve the
/// queries still out when a newer one completes.
const BASES_KEPT: usize = 64;

/// One leader's components at one cut, whole; shared between the kept
/// answers, since most components stay as they were from one to the next.
pub type Components = Arc<Vec<Arc<CountPart>>>;

/// What a marginals query found.
#[derive(Debug, Clone)]
pub(crate) struct Gathered {
    pub answer: MarginalsAnswer,
}

/// Every leader's share at one cut: all of them, at the same seq.
#[derive(Debug, Clone)]
pub struct Collected {
    pub cut: CutPlaced,
    pub parts: Vec<Partial>,
}

impl Collected {
    /// Every leader's rows of the information matrix, less the passive
    /// ones ([`Partial::passive`]) of tracks another leader's answer
    /// holds.
    pub fn rows(&self) -> Vec<&WireRow> {
        let rows: Vec<_> = self
            .parts
            .iter()
            .flat_map(|p| {
                p.rows
                    .iter()
                    .map(|r| (p.passive.as_slice(), std::slice::from_ref(&r.track), r))
            })
            .collect();
        without_passive(&rows)
    }

    /// Every leader's trees of the factored identity belief, less the
    /// passive ones (a start kept, [`Partial::passive`]) of tracks another
    /// leader's answer holds.
    pub fn trees(&self) -> Vec<&WireTree> {
        let n = self.cut.tracks;
        let trees: Vec<(&[u32], &WireTree)> = self
            .parts
            .iter()
            .flat_map(|p| p.trees.iter().map(|t| (p.passive.as_slice(), t)))
            .collect();
        let tracks: Vec<Vec<u32>> = trees.iter().map(|(_, t)| t.tracks(n).collect()).collect();
        let items: Vec<_> = trees
            .iter()
            .zip(&tracks)
            .map(|(&(passive, tree), tracks)| (passive, tracks.as_slice(), tree))
            .collect();
        without_passive(&items)
    }

    /// What the answer includes: per sensor, its events.
    pub(crate) fn watermark(&self) -> Watermark {
        if !self.cut.origins.is_empty() {
            return self.cut.origins.iter().cloned().collect();
        }
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
/// that was over, the count coupling of the last factored answer, and its
/// counts of bad input. Nothing is pushed to it; it only remembers what it
/// asked.
#[derive(Debug, Default)]
pub struct Memory {
    finished: Mutex<Option<CutPlaced>>,
    /// The count tree of the last factored answer: the next query redoes
    /// only the components that changed since (none, at rest). Queries
    /// take turns with it; computing is brief beside the gathering.
    coupling: Mutex<Option<Coupled>>,
    /// The last complete factored answers at fresh cuts, newest last: by
    /// cut tag, every leader's components whole. A query names the newest
    /// (`;base=`), and each leader answers with what changed since it.
    bases: Mutex<VecDeque<(u64, BTreeMap<String, Components>)>>,
    /// The last marginals answer and its JSON: a deployment at rest asked
    /// again gives the very same answer, and encoding 10,000 marginals
    /// costs more than gathering what changed. Shared bytes, so that a
    /// reply hands them to Zenoh without copying 200 kB.
    encoded: Mutex<Option<Encoded>>,
    /// Every sensor that has placed a cut: who is missing when none
    /// answers.
    sensors: Mutex<std::collections::BTreeSet<String>>,
    /// The newest epoch each leader role answered at, and each sensor
    /// role placed a cut at: a former holder's answer (cut off, still
    /// running) is refused.
    fence: Mutex<Fence>,
    rejected: AtomicU64,
    bad_replies: AtomicU64,
    degraded: AtomicU64,
    cuts_pushed: AtomicU64,
    cuts_asked: AtomicU64,
    query_repairs: AtomicU64,
}

impl Memory {
    /// Counts a query refused for its parameters.
    pub(crate) fn note_rejected(&self) {
        self.rejected.fetch_add(1, Ordering::Relaxed);
    }

    /// The fence on an answer (`what`) of `role` at `epoch`: why not, if
    /// it comes from a former holder of the role.
    pub(crate) fn admit_epoch(
        &self,
        what: &'static str,
        role: &str,
        epoch: u64,
    ) -> Result<(), Stale> {
        match self.fence.lock() {
            Ok(mut fence) => fence.admit(what, role, epoch),
            Err(_) => Ok(()),
        }
    }

    /// Counts a reply from another process that was no good.
    pub(crate) fn note_bad_reply(&self, what: &str, problem: &str) {
        let n = self.bad_replies.fetch_add(1, Ordering::Relaxed) + 1;
        tracing::warn!(what, problem, bad_replies = n, "bad reply");
    }

    /// Counts a query answered `degraded: …` (a leader missing or not
    /// at the cut).
    pub(crate) fn note_degraded(&self) {
        self.degraded.fetch_add(1, Ordering::Relaxed);
    }

    /// Counts a fresh cut whose sums every leader pushed (`true`), or one
    /// whose leaders had to be asked.
    pub(crate) fn note_cut(&self, pushed: bool) {
        let counter = if pushed {
            &self.cuts_pushed
        } else {
            &self.cuts_asked
        };
        counter.fetch_add(1, Ordering::Relaxed);
    }

    pub(crate) fn stats(&self) -> CoordinatorStats {
        CoordinatorStats {
            rejected: self.rejected.load(Ordering::Relaxed),
            bad_replies: self.bad_replies.load(Ordering::Relaxed),
            degraded: self.degraded.load(Ordering::Relaxed),
            cuts_pushed: self.cuts_pushed.load(Ordering::Relaxed),
            cuts_asked: self.cuts_asked.load(Ordering::Relaxed),
            query_repairs: self.query_repairs.load(Ordering::Relaxed),
        }
    }

    /// `answer` as JSON: the bytes kept from the last answer if it is the
    /// same (compared whole); if only the watermark moved (a stream asked
    /// at every cut, where most cuts change no component), the new
    /// watermark before the kept bytes of everything else; else encoded
    /// now. Kept with the answer, which is taken rather than copied.
    pub(crate) fn marginals_json(&self, answer: MarginalsAnswer) -> Bytes {
        let mut encoded = self.encoded.lock().unwrap_or_else(|e| e.into_inner());
        let size = match &*encoded {
            Some(last) if last.answer == answer => return last.bytes.clone(),
            Some(last) if last.after_watermark > 0 && same_but_watermark(&last.answer, &answer) => {
                let rest = &last.bytes[last.after_watermark..];
                let mut json = Vec::with_capacity(last.bytes.len() + 16);
                json.extend_from_slice(WATERMARK_OPENS);
                if serde_json::to_writer(&mut json, &answer.watermark).is_ok() {
                    let after_watermark = json.len();
                    json.extend_from_slice(rest);
                    let bytes = Bytes::from(json);
                    *encoded = Some(Encoded {
                        answer,
                        bytes: bytes.clone(),
                        after_watermark,
                    });
                    return bytes;
                }
                last.bytes.len()
            }
            Some(last) => last.bytes.len(),
            None => 0,
        };
        // About as long as the last: no regrowing of a 200 kB buffer.
        let mut json = Vec::with_capacity(size + size / 8);
        if serde_json::to_writer(&mut json, &answer).is_err() {
            json.clear();
        }
        // Where the watermark ends: the answer opens with it (the order of
        // `MarginalsAnswer`'s fields), and serde_json writes a map the
        // same alone as inside the answer; the next field follows a comma.
        // 0: not known, the next answer is encoded whole.
        let after_watermark = match serde_json::to_vec(&answer.watermark) {
            Ok(w) if json.starts_with(WATERMARK_OPENS) => WATERMARK_OPENS.len() + w.len(),
            _ => 0,
        };
        let after_watermark = match json.get(after_watermark) {
            Some(b',') => after_watermark,
            _ => 0,
        };
        let bytes = Bytes::from(json);
        *encoded = Some(Encoded {
            answer,
            bytes: bytes.clone(),
            after_watermark,
        });
        bytes
    }

    pub fn finished(&self) -> Option<CutPlaced> {
        self.finished.lock().ok().and_then(|c| c.clone())
    }

    /// No sensor answered: degraded, naming the sensors that did before,
    /// or a stream that has no source yet.
    pub(crate) fn no_sensor(&self) -> GatherError {
        let known: Vec<String> = self
            .sensors
            .lock()
            .map(|s| s.iter().cloned().collect())
            .unwrap_or_default();
        if known.is_empty() {
            GatherError::NoSensor
        } else {
            GatherError::SensorsDown(known)
        }
    }

    /// The tag of the newest answer kept, which a query names to the
    /// leaders as its base (`;base=`).
    pub fn base(&self) -> Option<u64> {
        let bases = self.bases.lock().unwrap_or_else(|e| e.into_inner());
        bases.back().map(|(tag, _)| *tag)
    }

    /// Keeps the components of the answer at the fresh cut tagged `tag`.
    fn keep(&self, tag: u64, components: BTreeMap<String, Components>) {
        let mut bases = self.bases.lock().unwrap_or_else(|e| e.into_inner());
        if bases.iter().any(|(t, _)| *t == tag) {
            return;
        }
        if bases.len() == BASES_KEPT {
            bases.pop_front();
        }
        bases.push_back((tag, components));
    }

    /// Keeps the components kept at tag `kept` as those of the answer at
    /// the cut tagged `tag` too (nothing changed between the two).
    fn keep_again(&self, kept: u64, tag: u64) {
        let components = {
            let bases = self.bases.lock().unwrap_or_else(|e| e.into_inner());
            bases
                .iter()
                .find(|(t, _)| *t == kept)
                .map(|(_, c)| c.clone())
        };
        if let Some(components) = components {
            self.keep(tag, components);
        }
    }

    /// Leader `p.leader`'s components whole: as sent, or its kept answer
    /// at `p.base` less the components `p.gone` and those it sent again,
    /// plus those it sent. None if that answer is no longer kept.
    fn whole(&self, p: &Partial, sent: &[CountPart]) -> Option<Components> {
        let Some(base) = p.base else {
            return Some(Arc::new(sent.iter().cloned().map(Arc::new).collect()));
        };
        let bases = self.bases.lock().unwrap_or_else(|e| e.into_inner());
        let (_, kept) = bases.iter().find(|(tag, _)| *tag == base)?;
        let before = kept.get(&p.leader)?;
        // Most leaders changed nothing since the base: their answer is it.
        if p.gone.is_empty() && sent.is_empty() {
            return Some(before.clone());
        }
        // A few first tracks against thousands of components: a sorted
        // list searched beats hashing every component's.
        let mut replaced: Vec<u32> = p
            .gone
            .iter()
            .copied()
            .chain(sent.iter().filter_map(|c| c.tracks.first().copied()))
            .collect();
        replaced.sort_unstable();
        let mut whole: Vec<Arc<CountPart>> = before
            .iter()
            .filter(|c| {
                c.tracks
                    .first()
                    .is_none_or(|t| replaced.binary_search(t).is_err())
            })
            .cloned()
            .collect();
        whole.extend(sent.iter().cloned().map(Arc::new));
        Some(Arc::new(whole))
    }

    pub fn remember(&self, cut: &CutPlaced) {
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

/// The parameters of the cut request of a fresh cut tagged `tag`.
pub(crate) fn cut_parameters(tag: u64, at: At, share: Share) -> String {
    let mut parameters = match at {
        At::Latest => format!("tag={tag}"),
        At::Events(n) => format!("tag={tag};events={n}"),
    };
    if share == Share::Rows {
        parameters.push_str(";rows");
    }
    parameters
}

/// What the sensor answered a cut request (`key`: where the answer came
/// from).
pub fn read_cut(
    reply: Result<Vec<u8>, String>,
    key: &str,
    memory: &Memory,
) -> Result<CutPlaced, GatherError> {
    match reply {
        Ok(bytes) => decode::<CutPlaced>(&bytes)
            .map_err(|e| {
                let problem = format!("{key}: {e}");
                memory.note_bad_reply("cut", &problem);
                GatherError::Failed(problem)
            })
            .inspect(|cut| {
                if let Ok(mut sensors) = memory.sensors.lock() {
                    sensors.insert(cut.sensor.clone());
                }
            }),
        // One sensor of several says it cannot place the cut without a
        // peer that is down: that is its answer, as it says it.
        Err(e) if e.starts_with("degraded") => Err(GatherError::Failed(e)),
        Err(e) => Err(GatherError::Failed(format!(
            "the sensor placed no cut: {e}"
        ))),
    }
}

/// The leaders' replies to one partial-sums query, as they come.
#[derive(Debug, Clone, Default)]
pub struct Partials {
    /// The tag asked for (None: where the leaders rest).
    tag: Option<u64>,
    parts: BTreeMap<String, Partial>,
    errors: Vec<String>,
}

impl Partials {
    pub fn new(tag: Option<u64>) -> Self {
        Partials {
            tag,
            ..Partials::default()
        }
    }

    /// One leader's reply (`key`: where it came from): its partial sums,
    /// or an error reply, or bytes that are no good (counted).
    pub fn reply(&mut self, reply: Result<Vec<u8>, String>, key: &str, memory: &Memory) {
        let tag = self.tag;
        match reply {
            Ok(bytes) => match decode::<Partial>(&bytes) {
                Ok(p) if tag.is_none_or(|t| t == p.tag) => {
                    // Two processes answering for one role: the one at
                    // the newest epoch holds it; the other is fenced off.
                    match memory.admit_epoch(Partial::WHAT, &p.leader, p.epoch) {
                        Ok(()) => {
                            self.parts.insert(p.leader.clone(), p);
                        }
                        Err(stale) => memory.note_bad_reply("partial sums", &stale.to_string()),
                    }
                }
                Ok(p) => self.errors.push(format!(
                    "leader {} answered tag {} for {tag:?}",
                    p.leader, p.tag
                )),
                Err(e) => {
                    let problem = format!("{key}: {e}");
                    memory.note_bad_reply("partial sums", &problem);
                    self.errors.push(problem);
                }
            },
            Err(e) => self.errors.push(e),
        }
    }

    /// How many leaders answered with sums.
    #[cfg(test)]
    pub(crate) fn answered(&self) -> usize {
        self.parts.len()
    }

    /// Whether every one of `leaders` answered with sums and no reply
    /// was an error or bad.
    pub(crate) fn complete(&self, leaders: &[String]) -> bool {
        self.errors.is_empty() && leaders.iter().all(|l| self.parts.contains_key(l))
    }

    /// Whether a reply was an error or bad.
    pub(crate) fn refused_any(&self) -> bool {
        !self.errors.is_empty()
    }

    /// The sums by leader, and the error replies.
    pub fn into_parts(self) -> (BTreeMap<String, Partial>, Vec<String>) {
        (self.parts, self.errors)
    }
}

/// The answer where the leaders rest, if every leader of `last` (the last
/// finished cut) rests at the same seq at the end of the stream (they then
/// hold the final belief: every set sent has been received). None sends
/// the query the long way.
pub fn at_rest_of(
    last: CutPlaced,
    parts: BTreeMap<String, Partial>,
    errors: Vec<String>,
    timeout: Duration,
    memory: &Memory,
) -> Option<Collected> {
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

/// The leaders' shares at `cut` if every leader answered there, or who is
/// missing or what went wrong: never a partial answer dressed as complete.
pub fn check(
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
        // A cut's answers carry no items.
        adopts: false,
    };
    for p in parts.values() {
        if let Err(e) = bounds.check_partial(p) {
            let problem = format!("{}: {e}", p.leader);
            memory.note_bad_reply("partial sums", &problem);
            errors.push(problem);
        }
    }
    // Sums from a process the sensor does not list (another stream's, a
    // stale one) would be added to the answer unnoticed.
    for p in parts.values().filter(|p| !cut.leaders.contains(&p.leader)) {
        let problem = format!("{} is not a leader of this stream", p.leader);
        memory.note_bad_reply("partial sums", &problem);
        errors.push(problem);
    }
    for p in parts.values().filter(|p| p.cut != cut.seq) {
        errors.push(format!(
            "leader {} answered at seq {} for a cut at {}",
            p.leader, p.cut, cut.seq
        ));
    }
    // Who did not answer at all is named first, every time: Zenoh's own
    // error reply at the timeout ("Timeout") names nobody, so it is left
    // out when the names say more.
    let missing: Vec<String> = cut
        .leaders
        .iter()
        .filter(|l| !parts.contains_key(*l) && !errors.iter().any(|e| names(e, l)))
        .cloned()
        .collect();
    if !missing.is_empty() {
        errors.retain(|e| e.trim() != "Timeout");
        return Err(GatherError::Missing {
            missing,
            timeout,
            others: errors,
        });
    }
    if !errors.is_empty() {
        return Err(GatherError::Refused(errors.join("; ")));
    }
    Ok(Collected {
        cut,
        parts: parts.into_values().collect(),
    })
}

/// Whether error reply `error` speaks for leader `leader`: the leaders'
/// own error replies say who they are ("leader leader-1 is recovering"),
/// which a mention of a peer ("waits for sets from leader-1") does not.
fn names(error: &str, leader: &str) -> bool {
    error.contains(&format!("leader {leader} "))
}

/// The last marginals answer given, its JSON, and where in the JSON its
/// watermark ends.
#[derive(Debug)]
struct Encoded {
    answer: MarginalsAnswer,
    bytes: Bytes,
    after_watermark: usize,
}

/// How a marginals answer's JSON opens: its first field is the watermark.
const WATERMARK_OPENS: &[u8] = b"{\"watermark\":";

/// Whether two answers differ at most in their watermarks.
fn same_but_watermark(a: &MarginalsAnswer, b: &MarginalsAnswer) -> bool {
    let MarginalsAnswer {
        watermark: _,
        tracks,
        red,
        p_red,
        predicted_red,
        leaders,
        coefficients,
        finished,
    } = a;
    *tracks == b.tracks
        && *red == b.red
        && *leaders == b.leaders
        && *coefficients == b.coefficients
        && *finished == b.finished
        && *predicted_red == b.predicted_red
        && *p_red == b.p_red
}

/// The property marginals the leaders' shares at one cut add up to.
pub fn marginals_of(
    collected: &Collected,
    memory: &Memory,
) -> Result<MarginalsAnswer, GatherError> {
    let cut = &collected.cut;
    let (p_red, predicted_red, coefficients) =
        if collected.parts.iter().any(|p| p.components.is_some()) {
            factored_marginals_of(collected, memory)?
        } else {
            let sums = combine(&collected.parts);
            let p_red = sums
                .marginals(cut.tracks as usize)
                .map_err(|_| GatherError::Degenerate)?;
            let predicted_red = predict_red(&p_red, cut.red.map(|k| k as usize));
            (p_red, predicted_red, sums.coefficients)
        };
    Ok(MarginalsAnswer {
        watermark: collected.watermark(),
        tracks: cut.tracks,
        red: cut.red,
        p_red,
        predicted_red,
        leaders: collected.parts.len() as u32,
        coefficients,
        finished: cut.finished,
    })
}

/// P(red) of a factored belief from every leader's components at one cut,
/// and the coefficients they hold: the count coupling, evaluated here on
/// demand (nothing global is computed between queries), from the count tree
/// the last query left in `memory`. Components that do not cover the field
/// exactly once (a leader of another stream, a bug) are refused by name.
fn factored_marginals_of(
    collected: &Collected,
    memory: &Memory,
) -> Result<(Vec<f64>, Vec<u32>, u64), GatherError> {
    let cut = &collected.cut;
    if let Some(p) = collected.parts.iter().find(|p| p.components.is_none()) {
        return Err(GatherError::Refused(format!(
            "leader {} answered with Radon sums on a factored stream",
            p.leader
        )));
    }
    let refused = |e| match e {
        BeliefError::Degenerate { .. } => GatherError::Degenerate,
        e => GatherError::Refused(format!("the leaders' components: {e}")),
    };
    let coefficients = collected.parts.iter().map(|p| p.coefficients).sum();
    let field = Field::with_count(cut.tracks as usize, cut.red.map(|k| k as usize), None);
    let mut kept = memory.coupling.lock().unwrap_or_else(|e| e.into_inner());
    // Every leader says nothing changed since the answer whose parts the
    // tree holds (a deployment at rest, asked again): that answer stands.
    // At a fresh cut it is this cut's answer too, kept under its tag:
    // leaders that push their answers tell the next one as a change to it.
    let tag = collected.parts.first().map(|p| p.tag).filter(|&t| t != 0);
    if let Some(last) = kept
        .as_mut()
        .and_then(|k| k.unchanged(&field, &collected.parts))
    {
        if let Some(tag) = tag {
            memory.keep_again(last.tag, tag);
            last.tag = tag;
        }
        return Ok((last.p_red.clone(), last.predicted_red.clone(), coefficients));
    }
    let coupled = match &mut *kept {
        Some(k) if *k.tree.field() == field => k,
        other => other.insert(Coupled {
            tree: CouplingTree::new(field.clone()).map_err(refused)?,
            last: None,
        }),
    };
    coupled.last = None;
    let mut whole = BTreeMap::new();
    for p in &collected.parts {
        let sent = p.components.as_deref().unwrap_or_default();
        let components = memory
            .whole(p, sent)
            .ok_or_else(|| GatherError::StaleBase {
                leader: p.leader.clone(),
                base: p.base.unwrap_or_default(),
            })?;
        whole.insert(p.leader.clone(), components);
    }
    let repairs = coupled.tree.repairs();
    let p_red = coupled
        .tree
        .marginals_shared(held_parts(&whole, &collected.parts).into_iter())
        .map_err(refused)?;
    let repaired = coupled.tree.repairs() - repairs;
    memory.query_repairs.fetch_add(repaired, Ordering::Relaxed);
    let predicted_red = predict_red(&p_red, cut.red.map(|k| k as usize));
    // An answer at a fresh cut (tag ≠ 0; at rest the leaders answer with
    // tag 0) is what later queries name as their base.
    if let Some(tag) = tag {
        coupled.last = Some(LastCoupled {
            tag,
            p_red: p_red.clone(),
            predicted_red: predicted_red.clone(),
        });
        drop(kept);
        memory.keep(tag, whole);
    }
    Ok((p_red, predicted_red, coefficients))
}

/// Every leader's parts, less the passive ones ([`Partial::passive`]) of
/// tracks another leader's answer holds.
fn held_parts<'a>(
    whole: &'a BTreeMap<String, Components>,
    answers: &'a [Partial],
) -> Vec<&'a Arc<CountPart>> {
    let passive = |leader: &str| {
        answers
            .iter()
            .find(|p| p.leader == leader)
            .map_or(&[][..], |p| p.passive.as_slice())
    };
    let parts: Vec<_> = whole
        .iter()
        .flat_map(|(l, c)| {
            let kept = passive(l);
            c.iter().map(move |c| (kept, c.tracks.as_slice(), c))
        })
        .collect();
    without_passive(&parts)
}

/// Of `items` (parts or rows, each with the passive tracks of the answer
/// it came in and the tracks it holds), all but the passive ones — a part
/// or row of one track its answer lists as passive — of tracks another
/// item holds: a keeper is not told that a track it keeps was adopted
/// elsewhere.
fn without_passive<T: Copy>(items: &[(&[u32], &[u32], T)]) -> Vec<T> {
    let is_passive = |passive: &[u32], tracks: &[u32]| {
        tracks.len() == 1 && passive.binary_search(&tracks[0]).is_ok()
    };
    let held: BTreeSet<u32> = items
        .iter()
        .filter(|(passive, tracks, _)| !is_passive(passive, tracks))
        .flat_map(|(_, tracks, _)| tracks.iter().copied())
        .collect();
    items
        .iter()
        .filter(|(passive, tracks, _)| !(is_passive(passive, tracks) && held.contains(&tracks[0])))
        .map(|&(_, _, item)| item)
        .collect()
}

/// The coordinator's count coupling between queries, and the answer it
/// last gave at a fresh cut while the tree still holds that cut's parts.
#[derive(Debug)]
struct Coupled {
    tree: CouplingTree,
    last: Option<LastCoupled>,
}

#[derive(Debug)]
struct LastCoupled {
    /// The tag of the cut whose parts the tree holds.
    tag: u64,
    p_red: Vec<f64>,
    predicted_red: Vec<u32>,
}

impl Coupled {
    /// The last answer, if `parts` are all told as no change since it.
    fn unchanged(&mut self, field: &Field, parts: &[Partial]) -> Option<&mut LastCoupled> {
        let last = self.last.as_mut()?;
        let same = self.tree.field() == field
            && parts.iter().all(|p| {
                p.base == Some(last.tag)
                    && p.gone.is_empty()
                    && p.components.as_ref().is_some_and(|c| c.is_empty())
            });
        same.then_some(last)
    }
}

#[cfg(test)]
mod tests;
