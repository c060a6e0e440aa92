//! The coordinator's part of a schedule, as `coordinator/src/driver/`
//! runs it: a query's two phases (the leaders' answers at rest, then a
//! cut and the fresh ones), and every answer checked against the
//! centralized engine at its watermark.

use super::leader::{ToLeader, Who};
use super::sensor::ToSensor;
use super::{Event, Msg, World, QUERY_TIMEOUT};
use crate::sim::network::Endpoint;
use crate::sim::scenario::exact_marginals;
use crate::sim::Violation;
use idmesh_coordinator::machine::{
    at_rest_of, check, marginals_of, read_cut, GatherError, Partials,
};
use idmesh_identity::factored::assemble;
use idmesh_identity::{IdentityFilter, InformationOptions, InformationRows};
use idmesh_leader::Ask;
use idmesh_placement::{from_wire_tree, identity_options};
use idmesh_protocol::wire::coordinator_to_leader::Partial;
use idmesh_protocol::wire::coordinator_to_sensor::CutPlaced;
use idmesh_protocol::wire::decode;
use idmesh_protocol::wire::identity::WireTree;
use idmesh_protocol::wire::query::MarginalsAnswer;
use idmesh_sensor::CutParameters;
use rand::Rng;
use std::collections::BTreeSet;
use std::time::Duration;

#[derive(Debug, Clone)]
pub(crate) enum ToCoordinator {
    Cut {
        id: u64,
        reply: Result<Vec<u8>, String>,
    },
    Partial {
        id: u64,
        from: Who,
        reply: Result<Vec<u8>, String>,
    },
}

/// A query of the coordinator, in one of its two phases.
pub(super) struct Query {
    /// Answers completed before it started had at most this watermark.
    pub(super) floor: u64,
    pub(super) last: Option<CutPlaced>,
    pub(super) phase: Phase,
    /// Ids of the current phase (messages of an earlier phase are stale).
    pub(super) id: u64,
    /// The tag of the current phase's cut (None: at rest).
    pub(super) tag: Option<u64>,
    /// Who replied in this phase (a role's former holder answers too).
    pub(super) replied: BTreeSet<Who>,
    pub(super) partials: Partials,
    pub(super) cut: Option<Result<CutPlaced, GatherError>>,
    pub(super) final_query: bool,
}

#[derive(PartialEq, Eq)]
pub(super) enum Phase {
    Rest,
    Fresh,
}

impl World {
    pub(super) fn start_query(&mut self, final_query: bool) {
        let id = self.fresh_id();
        let last = self.memory.finished();
        let mut query = Query {
            floor: self.answered_events,
            last: last.clone(),
            phase: Phase::Rest,
            id,
            tag: None,
            replied: BTreeSet::new(),
            partials: Partials::new(None),
            cut: None,
            final_query,
        };
        match last {
            Some(_) => {
                for j in 0..self.leaders.len() {
                    let rows = self.scenario.identity.is_some();
                    self.ask_leader(j, id, Ask::Quiet { rows });
                }
            }
            None => self.fresh_phase(&mut query),
        }
        self.net
            .at(self.now + QUERY_TIMEOUT, Event::QueryTimeout(query.id));
        self.queries.insert(query.id, query);
    }

    pub(super) fn fresh_phase(&mut self, query: &mut Query) {
        let id = self.fresh_id();
        let tag = self.rng.gen::<u64>();
        query.phase = Phase::Fresh;
        query.id = id;
        query.tag = Some(tag);
        query.replied.clear();
        query.partials = Partials::new(Some(tag));
        query.cut = None;
        self.send(
            Endpoint::Coordinator,
            Endpoint::Sensor,
            Msg::Sensor {
                from: Who::holder(usize::MAX),
                epoch: 0,
                what: ToSensor::Cut {
                    id,
                    parameters: CutParameters {
                        tag: Some(tag.to_string()),
                        // An identity stream's cuts carry the rows too:
                        // every answer is checked for both.
                        rows: self.scenario.identity.is_some(),
                        events: None,
                    },
                },
            },
        );
        for j in 0..self.leaders.len() {
            self.ask_leader(j, id, Ask::Cut(tag));
        }
    }

    pub(super) fn ask_leader(&mut self, j: usize, id: u64, ask: Ask) {
        self.send(
            Endpoint::Coordinator,
            Endpoint::Leader(j),
            Msg::Leader {
                to: j,
                what: ToLeader::Partial {
                    id,
                    ask,
                    // As the coordinator does: the leaders answer with
                    // what changed since the newest answer it keeps.
                    base: self.memory.base(),
                },
            },
        );
    }

    pub(super) fn at_coordinator(&mut self, what: ToCoordinator) -> Result<(), Violation> {
        let (id, done) = match what {
            ToCoordinator::Cut { id, reply } => {
                let Some(query) = self.queries.get_mut(&id) else {
                    return Ok(());
                };
                if query.cut.is_none() {
                    query.cut = Some(read_cut(reply, "sim/cut", &self.memory));
                }
                // No cut, no answer: an error there stops the wait.
                let failed = matches!(query.cut, Some(Err(_)));
                let all = holders_replied(&query.replied) == self.leaders.len();
                (id, failed || all)
            }
            ToCoordinator::Partial { id, from, reply } => {
                if self
                    .queries
                    .get(&id)
                    .is_none_or(|q| q.replied.contains(&from))
                {
                    // Over, or a duplicate: Zenoh would not deliver it twice.
                    return Ok(());
                }
                self.partial_reply(id, from, reply)?;
                let Some(query) = self.queries.get(&id) else {
                    return Ok(());
                };
                let all = holders_replied(&query.replied) == self.leaders.len();
                (
                    id,
                    all && (query.phase == Phase::Rest || query.cut.is_some()),
                )
            }
        };
        if done {
            self.complete_query(id)?;
        }
        Ok(())
    }

    /// `from`'s reply to query `id` (whose phase it is). Its epoch must be
    /// one the map gave the role; if the coordinator had been handed a
    /// newer epoch's answer of that role, it must not keep it (counted as
    /// fenced).
    fn partial_reply(
        &mut self,
        id: u64,
        from: Who,
        reply: Result<Vec<u8>, String>,
    ) -> Result<(), Violation> {
        let Some(query) = self.queries.get_mut(&id) else {
            return Ok(());
        };
        query.replied.insert(from);
        let partial = reply
            .as_ref()
            .ok()
            .and_then(|bytes| decode::<Partial>(bytes).ok());
        let Some(p) = partial else {
            query.partials.reply(reply, "sim/partial", &self.memory);
            return Ok(());
        };
        if p.base.is_some() {
            self.tally.changes += 1;
        }
        let role = from.role;
        if !self.hosts.held.contains_key(&(role, p.epoch)) {
            return Err(Violation::new(format!(
                "{} answered at epoch {}, which no process was given",
                p.leader, p.epoch
            )));
        }
        let tagged = query.tag.is_none_or(|t| t == p.tag);
        let heard = self.coordinator_heard.get(&p.leader).copied();
        let Some(newest) = heard.filter(|&h| tagged && p.epoch < h) else {
            query.partials.reply(reply, "sim/partial", &self.memory);
            if tagged {
                let heard = self.coordinator_heard.entry(p.leader).or_insert(p.epoch);
                *heard = (*heard).max(p.epoch);
            }
            return Ok(());
        };
        let kept = |partials: &Partials| partials.clone().into_parts().0.remove(&p.leader);
        let before = kept(&query.partials);
        query.partials.reply(reply, "sim/partial", &self.memory);
        if kept(&query.partials) != before {
            return Err(Violation::new(format!(
                "the coordinator kept {}'s answer at epoch {}, older than the epoch {newest} it had heard",
                p.leader, p.epoch
            )));
        }
        self.tally.fenced += 1;
        Ok(())
    }

    /// The phase of query `id` is over (all answered, or its time is up).
    pub(super) fn complete_query(&mut self, id: u64) -> Result<(), Violation> {
        let Some(mut query) = self.queries.remove(&id) else {
            return Ok(());
        };
        let timeout = Duration::from_millis(QUERY_TIMEOUT);
        let partials = std::mem::take(&mut query.partials);
        let (parts, errors) = partials.into_parts();
        let result = match query.phase {
            Phase::Rest => {
                let last = query.last.clone().expect("a rest phase has a last cut");
                match at_rest_of(last, parts, errors, timeout, &self.memory) {
                    Some(collected) => Ok(collected),
                    None => {
                        self.fresh_phase(&mut query);
                        self.net
                            .at(self.now + QUERY_TIMEOUT, Event::QueryTimeout(query.id));
                        self.queries.insert(query.id, query);
                        return Ok(());
                    }
                }
            }
            Phase::Fresh => match query.cut.take() {
                None => Err(GatherError::NoSensor),
                Some(Err(e)) => Err(e),
                Some(Ok(cut)) => check(cut, parts, errors, timeout, &self.memory).inspect(|c| {
                    self.memory.remember(&c.cut);
                }),
            },
        };
        let answered = result.and_then(|collected| {
            let answer = marginals_of(&collected, &self.memory)?;
            let rows: Vec<(u32, Vec<f64>)> = collected
                .rows()
                .into_iter()
                .map(|r| (r.track, r.ln_likelihoods.clone()))
                .collect();
            let trees: Vec<WireTree> = collected.trees().into_iter().cloned().collect();
            Ok((answer, (rows, trees)))
        });
        match answered {
            Ok((answer, (rows, trees))) => {
                if self.scenario.identity.is_some() {
                    let events = answer.watermark.values().copied().sum::<u64>();
                    self.answered_identity(events, rows, trees)?;
                }
                self.answered(&query, answer)
            }
            Err(e) => {
                self.tally.failed_queries += 1;
                self.last_error = e.to_string();
                if query.final_query {
                    // Ask again shortly, as a user would.
                    self.net.at(self.now + 500, Event::Calm);
                    self.calm = true;
                }
                Ok(())
            }
        }
    }

    /// Checks an answer against the centralized engine and the answers
    /// before it.
    pub(super) fn answered(
        &mut self,
        query: &Query,
        answer: MarginalsAnswer,
    ) -> Result<(), Violation> {
        self.tally.answered += 1;
        let events = answer.watermark.values().copied().sum::<u64>();
        let sum: f64 = answer.p_red.iter().sum();
        if (sum - self.scenario.red as f64).abs() > 1e-9 {
            return Err(Violation::new(format!(
                "marginals sum to {sum}, not k = {}: {:?}",
                self.scenario.red, answer.p_red
            )));
        }
        if events < query.floor {
            return Err(Violation::new(format!(
                "the watermark went back: {events} after an answer at {}",
                query.floor
            )));
        }
        let Some(want) = self.scenario.centralized.get(events as usize) else {
            return Err(Violation::new(format!(
                "an answer at {events} events, beyond the stream's {}",
                self.scenario.lines.len()
            )));
        };
        for (t, (got, want)) in answer.p_red.iter().zip(want).enumerate() {
            if (got - want).abs() > 1e-9 {
                return Err(Violation::new(format!(
                    "at {events} events track {t}: the deployment says {got}, the centralized engine {want}\n  deployment {:?}\n  centralized {want:?}",
                    answer.p_red
                )));
            }
        }
        self.answered_events = self.answered_events.max(events);
        if query.final_query {
            if events != self.scenario.lines.len() as u64 || !answer.finished {
                return Err(Violation::new(format!(
                    "the final answer is at {events} events of {} (finished: {})",
                    self.scenario.lines.len(),
                    answer.finished
                )));
            }
            self.final_answer = Some(answer);
        }
        Ok(())
    }

    /// Checks the rows or trees an answer at `events` events gathered
    /// against the centralized identity belief there: rows put together
    /// must be the information matrix (the same operations on each row, in
    /// the same order), trees put together the factored identity belief,
    /// and the identity answer made of them must be its.
    pub(super) fn answered_identity(
        &mut self,
        events: u64,
        rows: Vec<(u32, Vec<f64>)>,
        trees: Vec<WireTree>,
    ) -> Result<(), Violation> {
        let Some(central) = &self.scenario.identity else {
            return Ok(());
        };
        let Some(want_marginals) = central.marginals.get(events as usize) else {
            return Err(Violation::new(format!(
                "an identity answer at {events} events, beyond the stream's {}",
                self.scenario.lines.len()
            )));
        };
        let Some(all_rows) = &central.rows else {
            if !rows.is_empty() {
                return Err(Violation::new(format!(
                    "at {events} events rows of an information matrix where the leaders hold trees"
                )));
            }
            let n = want_marginals.len();
            let held = trees
                .into_iter()
                .map(from_wire_tree)
                .collect::<Result<Vec<_>, _>>()
                .map_err(|e| Violation::new(format!("at {events} events a tree: {e}")))?;
            let cap = self.scenario.identity_cap;
            let whole = assemble(n, identity_options(cap), held).map_err(|e| {
                Violation::new(format!(
                    "at {events} events the leaders' trees do not make a belief: {e}"
                ))
            })?;
            let marginals = whole
                .marginals()
                .map_err(|e| Violation::new(e.to_string()))?;
            for (t, (got, want)) in marginals.iter().zip(want_marginals).enumerate() {
                if !got.iter().zip(want).all(|(g, w)| (g - w).abs() <= 1e-9) {
                    return Err(Violation::new(format!(
                        "at {events} events track {t}'s identities: the deployment's trees say {got:?}, the centralized factored identity belief {want:?}"
                    )));
                }
            }
            self.tally.identity_answers += 1;
            self.tally.tree_answers += 1;
            return Ok(());
        };
        let Some(want) = all_rows.get(events as usize) else {
            return Err(Violation::new(format!(
                "an identity answer at {events} events, beyond the stream's {}",
                self.scenario.lines.len()
            )));
        };
        let n = want.len();
        let held: Vec<u32> = rows.iter().map(|(t, _)| *t).collect();
        let matrix = InformationRows::assemble(n, rows, InformationOptions::default())
            .map_err(|e| {
                Violation::new(format!(
                    "at {events} events the leaders' rows (of tracks {held:?}) do not make a matrix: {e}"
                ))
            })?;
        let close = |got: f64, want: f64| got == want || (got - want).abs() <= 1e-9;
        let got = matrix.log_likelihoods();
        for (t, (got, want)) in got.iter().zip(want).enumerate() {
            if got.len() != want.len() || !got.iter().zip(want).all(|(g, w)| close(*g, *w)) {
                return Err(Violation::new(format!(
                    "at {events} events the row of track {t}: the deployment has {got:?}, the centralized information matrix {want:?}"
                )));
            }
        }
        let marginals = exact_marginals(&matrix).map_err(Violation::new)?;
        for (t, (got, want)) in marginals.iter().zip(want_marginals).enumerate() {
            if !got.iter().zip(want).all(|(g, w)| (g - w).abs() <= 1e-9) {
                return Err(Violation::new(format!(
                    "at {events} events track {t}'s identities: the deployment says {got:?}, the centralized engine {want:?}"
                )));
            }
        }
        self.tally.identity_answers += 1;
        Ok(())
    }
}

/// How many roles' current holders replied (a former holder's reply
/// counts for nothing: the query waits for the role's holder).
fn holders_replied(replied: &BTreeSet<Who>) -> usize {
    replied.iter().filter(|w| !w.former).count()
}
