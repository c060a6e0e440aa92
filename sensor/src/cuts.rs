//! Cuts asked for by the coordinator (`P/sensor/<name>/cut?tag=T`): placed
//! at once, or, with `&events=N`, at the point of the stream where the N-th
//! event has been read (a query about a moment that has not come yet: the
//! scoring of a live deployment against the truth lines uses it). A point
//! already passed cannot be given back: the stream keeps no history. With
//! `;rows` (an identity query) the cut asks the leaders for their rows of
//! the information matrix too.

use crate::router::Router;
use idmesh_protocol::wire::coordinator_to_sensor::CutPlaced;
use idmesh_protocol::wire::VERSION;
use std::collections::BTreeMap;

/// Cuts waiting for their event count, at most this many.
const MAX_SCHEDULED: usize = 10_000;

/// The cut a query asks for: its tag, and whether leaders add their rows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Wanted {
    pub tag: u64,
    pub rows: bool,
}

/// A cut request's parameters (`tag=T`, `;rows`, `;events=N`), as text.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct CutParameters {
    pub tag: Option<String>,
    pub rows: bool,
    pub events: Option<String>,
}

impl CutParameters {
    /// The cut they ask for and the event count it is wanted at (None:
    /// now), or why they do not read.
    pub fn parse(&self) -> Result<(Wanted, Option<u64>), String> {
        let tag = self
            .tag
            .as_deref()
            .and_then(|t| t.parse::<u64>().ok())
            .ok_or("a cut needs tag=<u64>: the tag leaders will be asked for")?;
        let at = self
            .events
            .as_deref()
            .map(str::parse::<u64>)
            .transpose()
            .map_err(|_| "events=<n> must be a count of events")?;
        Ok((
            Wanted {
                tag,
                rows: self.rows,
            },
            at,
        ))
    }
}

/// What to do with a cut request; `Q` is whatever the driver answers
/// (a Zenoh query, a simulated one).
pub(crate) enum Request<Q> {
    /// Place it now.
    Now { wanted: Wanted, query: Q },
    /// Held until the stream reaches its point.
    Scheduled,
    /// Refused, with the reason (a point the stream cannot give).
    Refused { query: Q, reason: String },
    /// Malformed parameters: bad input, refused and counted like any.
    Malformed { query: Q, reason: String },
}

#[derive(Debug, serde::Serialize, serde::Deserialize)]
pub(crate) struct Cuts<Q> {
    scheduled: BTreeMap<u64, Vec<(Wanted, Q)>>,
    held: usize,
    /// The event count the stream will end at, when known in advance (a
    /// trace file, or `events =` in the topology): a point beyond it is
    /// refused at once instead of waiting out the query's timeout.
    end: Option<u64>,
}

impl<Q> Default for Cuts<Q> {
    fn default() -> Self {
        Cuts {
            scheduled: BTreeMap::new(),
            held: 0,
            end: None,
        }
    }
}

/// A cut placed in the stream, and the query to tell once it is sent.
pub struct Placed<Q> {
    pub query: Q,
    /// The cut it placed (what the sensor journals).
    pub wanted: Wanted,
    pub answer: CutPlaced,
}

impl<Q> Cuts<Q> {
    /// Cuts for a stream that will end after `end` events.
    pub(crate) fn ending_at(end: u64) -> Self {
        Cuts {
            end: Some(end),
            ..Cuts::default()
        }
    }

    /// Sorts a request: now, later, or never.
    pub(crate) fn request(
        &mut self,
        query: Q,
        parameters: &CutParameters,
        router: &Router,
        finished: bool,
    ) -> Request<Q> {
        match parameters.parse() {
            Ok((wanted, at)) => self.sort(query, wanted, at, router, finished),
            Err(reason) => Request::Malformed { query, reason },
        }
    }

    /// Sorts the cut `wanted` at event count `at` (None: now): now, later,
    /// or never.
    pub fn sort(
        &mut self,
        query: Q,
        wanted: Wanted,
        at: Option<u64>,
        router: &Router,
        finished: bool,
    ) -> Request<Q> {
        let Some(at) = at else {
            return Request::Now { wanted, query };
        };
        let now = router.events();
        if at == now {
            return Request::Now { wanted, query };
        }
        let reason = if at < now {
            format!("the stream is past event {at} (it is at {now}) and keeps no history")
        } else if finished {
            format!("the stream ended at {now} events, before event {at}")
        } else if let Some(end) = self.end.filter(|&end| at > end) {
            format!("the stream ends at {end} events, before event {at}")
        } else if self.held >= MAX_SCHEDULED {
            format!("{MAX_SCHEDULED} cuts are already waiting for their point")
        } else {
            self.scheduled.entry(at).or_default().push((wanted, query));
            self.held += 1;
            return Request::Scheduled;
        };
        Request::Refused { query, reason }
    }

    /// Whether a cut tagged `tag` waits for its point.
    pub(crate) fn holds(&self, tag: u64) -> bool {
        self.scheduled
            .values()
            .any(|waiting| waiting.iter().any(|(w, _)| w.tag == tag))
    }

    /// Places the cuts whose point the router has reached (call after each
    /// line), adding them to `placed`, as sensor `name` at `epoch`.
    pub(crate) fn reached(
        &mut self,
        router: &mut Router,
        (name, epoch): (&str, u64),
        placed: &mut Vec<Placed<Q>>,
    ) {
        while let Some(entry) = self.scheduled.first_entry() {
            if *entry.key() > router.events() {
                return;
            }
            for (wanted, query) in entry.remove() {
                self.held -= 1;
                placed.push(place(router, (name, epoch), wanted, query, false));
            }
        }
    }

    /// The stream is over: every cut still waiting is refused.
    pub(crate) fn refuse_all(&mut self, router: &Router) -> Vec<(Q, String)> {
        self.held = 0;
        std::mem::take(&mut self.scheduled)
            .into_iter()
            .flat_map(|(at, waiting)| {
                waiting.into_iter().map(move |(_, query)| {
                    (
                        query,
                        format!(
                            "the stream ended at {} events, before event {at}",
                            router.events()
                        ),
                    )
                })
            })
            .collect()
    }
}

/// Places the cut a query wants in every leader's stream now, as sensor
/// `name` holding its role at `epoch` (the coordinator fences on it).
pub(crate) fn place<Q>(
    router: &mut Router,
    (name, epoch): (&str, u64),
    wanted: Wanted,
    query: Q,
    finished: bool,
) -> Placed<Q> {
    let (seq, events) = router.cut(wanted);
    let begin = router.begin();
    Placed {
        query,
        wanted,
        answer: CutPlaced {
            version: VERSION,
            epoch,
            sensor: name.to_string(),
            seq,
            events,
            leaders: begin.leaders.clone(),
            tracks: begin.tracks,
            red: begin.red,
            finished,
            identities: begin.identities,
            origins: Vec::new(),
        },
    }
}
