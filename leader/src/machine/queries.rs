//! The coordinator's partial-sums queries: answered at once, refused, or
//! held until the cut with their tag reaches the leader in its stream
//! (the coordinator asks the sensor to place the cut and the leaders to
//! answer at it in the same breath, so a query usually comes first).

use super::{Held, Node, Now, Output};
use crate::state::Answer;
use idmesh_protocol::wire::coordinator_to_leader::Partial;
use std::sync::Arc;
use std::time::Duration;

/// What a partial-sums query asks for (`?tag=T`, `?quiet`, `;rows`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Ask {
    /// The partial sums at the cut tagged `tag`.
    Cut(u64),
    /// Where the leader rests, if it does; with its rows when `rows`.
    Quiet { rows: bool },
    /// A query that says neither, and why it cannot be answered.
    Bad(String),
}

impl Ask {
    /// Reads a query's parameters: whether it has `quiet` and `rows`, its
    /// `tag` if any, and its `base` if any: the tag of this leader's answer
    /// the coordinator keeps, so a factored answer may be told as a change
    /// to it ([`Partial::base`](idmesh_protocol::wire::coordinator_to_leader::Partial::base)).
    pub(crate) fn parse_with_base(
        quiet: bool,
        rows: bool,
        tag: Option<&str>,
        base: Option<&str>,
    ) -> (Ask, Option<u64>) {
        match base.map(|b| b.parse::<u64>()) {
            None => (Ask::parse(quiet, rows, tag), None),
            Some(Ok(base)) => (Ask::parse(quiet, rows, tag), Some(base)),
            Some(Err(_)) => (
                Ask::Bad(format!(
                    "base={} is not the tag of an answer (a u64)",
                    base.unwrap_or_default()
                )),
                None,
            ),
        }
    }

    /// [`Ask::parse_with_base`] without a base.
    pub fn parse(quiet: bool, rows: bool, tag: Option<&str>) -> Ask {
        if quiet {
            return Ask::Quiet { rows };
        }
        match tag.and_then(|t| t.parse::<u64>().ok()) {
            Some(tag) => Ask::Cut(tag),
            None => Ask::Bad(
                "a partial-sums query needs tag=<u64> (the tag of the cut it asks for) or quiet"
                    .into(),
            ),
        }
    }
}

impl Node {
    /// Answers query `id` (as a change to the answer at the cut tagged
    /// `base`, when it can), or holds it for its cut.
    pub(super) fn partial(
        &mut self,
        now: Now,
        id: u64,
        ask: Ask,
        base: Option<u64>,
        out: &mut Vec<Output>,
    ) {
        let name = self.leader.name().to_string();
        let answer = if let Some(failure) = &self.failure {
            Err(format!("leader {name} failed: {failure}"))
        } else if let (Some(since), Some(why)) = (self.recovering_since(), self.unrebuildable()) {
            Err(format!(
                "degraded: leader {name} has been recovering its state for {:.1} s and cannot \
                 be rebuilt from the stream: {why}",
                now.saturating_sub(since).as_secs_f64()
            ))
        } else if let Some(since) = self.recovering_since() {
            Err(format!(
                "degraded: leader {name} is recovering its state (for {:.1} s); ask again shortly",
                now.saturating_sub(since).as_secs_f64()
            ))
        } else {
            match ask {
                Ask::Bad(why) => {
                    // Bad input like any other: logged and counted.
                    self.count_rejected("a partial-sums query", "the coordinator", &why, out);
                    Err(why)
                }
                Ask::Quiet { rows } => self
                    .leader
                    .quiet_kept(rows)
                    .map(|partial| self.told(&partial, base))
                    .ok_or_else(|| format!("leader {name} is not at a quiet point")),
                Ask::Cut(tag) => match self.leader.cut(tag) {
                    Some(partial) => Ok(self.told(partial, base)),
                    None => {
                        self.held.push(Held {
                            id,
                            tag,
                            base,
                            since: now,
                        });
                        return;
                    }
                },
            }
        };
        out.push(Output::Answer { id, answer });
    }

    /// `answer` as a change to this leader's answer at the cut tagged
    /// `base` if that answer is still kept and both are factored; whole
    /// otherwise (the coordinator rebuilds either).
    pub(super) fn told(&self, answer: &Answer, base: Option<u64>) -> Arc<Partial> {
        base.and_then(|b| self.leader.relative_to(answer, b))
            .map(Arc::new)
            .unwrap_or_else(|| answer.whole())
    }

    /// Answers with an error every query that has waited for its cut
    /// longer than [`Node::hold_for`], saying what the leader waits for
    /// (a peer's transfer, the sensor's batches), so that the
    /// coordinator can name who is missing before it gives up itself.
    pub(super) fn expire(&mut self, now: Now, out: &mut Vec<Output>) {
        let patience = self.hold_for();
        let expired: Vec<Held> = self
            .held
            .extract_if(.., |h| now.saturating_sub(h.since) > patience)
            .collect();
        if expired.is_empty() {
            return;
        }
        let why = self.stuck_on();
        let name = self.leader.name().to_string();
        for h in expired {
            out.push(Output::Answer {
                id: h.id,
                answer: Err(format!(
                    "degraded: leader {name} did not reach the cut tagged {} within {patience:?}: {why}",
                    h.tag
                )),
            });
        }
    }

    /// How long a query is held for its cut: the query timeout less two
    /// sweeps (the tick that notices it, and the way back), so the reply
    /// naming what is missing reaches the coordinator before the
    /// coordinator's own timeout, which would only say "Timeout"; never
    /// less than half the timeout.
    pub(super) fn hold_for(&self) -> Duration {
        let timeout = self.timers.query_timeout;
        timeout
            .saturating_sub(2 * self.timers.sweep)
            .max(timeout / 2)
    }

    /// What keeps this leader from its stream's head, in words.
    pub(super) fn stuck_on(&self) -> String {
        if let Some((seq, from)) = self.leader.waiting_for_transfer() {
            let peer = self.leader.peer(from).unwrap_or("an unknown leader");
            return format!("it waits for sets from {peer} at item {seq}");
        }
        if let Some(seq) = self.leader.waiting_for_components() {
            return format!("it waits for the components of the mix at item {seq}");
        }
        let sensor = self
            .leader
            .sensor()
            .map_or_else(|| "the sensor".to_string(), |s| format!("sensor {s}"));
        if let Some(next) = self.leader.missing_batches() {
            return format!("it waits for batch {next} from {sensor}");
        }
        format!(
            "no batch with the cut came from {sensor} (its last applied item is {})",
            self.leader.position()
        )
    }
}
