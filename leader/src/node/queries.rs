//! The coordinator's partial-sums queries: answered at once, refused, or
//! held until the cut with their tag reaches the leader in its stream
//! (the coordinator asks the sensor to place the cut and the leaders to
//! answer at it in the same breath, so a query usually comes first).

use super::{Held, Node, Now, Output};

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
    /// Reads a query's parameters: whether it has `quiet` and `rows`, and
    /// its `tag` if any.
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
    /// Answers query `id`, or holds it for its cut.
    pub(super) fn partial(&mut self, now: Now, id: u64, ask: Ask, out: &mut Vec<Output>) {
        let name = self.leader.name();
        let answer = if let Some(failure) = &self.failure {
            Err(format!("leader {name} failed: {failure}"))
        } else if let Some(since) = self.recovering_since() {
            Err(format!(
                "degraded: leader {name} is recovering its state (for {:.1} s); ask again shortly",
                now.saturating_sub(since).as_secs_f64()
            ))
        } else {
            match ask {
                Ask::Bad(why) => Err(why),
                Ask::Quiet { rows } => self
                    .leader
                    .quiet(rows)
                    .ok_or_else(|| format!("leader {name} is not at a quiet point")),
                Ask::Cut(tag) => match self.leader.cut(tag) {
                    Some(partial) => Ok(partial.clone()),
                    None => {
                        self.held.push(Held {
                            id,
                            tag,
                            since: now,
                        });
                        return;
                    }
                },
            }
        };
        out.push(Output::Answer { id, answer });
    }

    /// Answers with an error every query that has waited longer than the
    /// query timeout for its cut (the sensor never placed it, or the
    /// stream is stuck).
    pub(super) fn expire(&mut self, now: Now, out: &mut Vec<Output>) {
        let timeout = self.timers.query_timeout;
        let expired: Vec<Held> = self
            .held
            .extract_if(.., |h| now.saturating_sub(h.since) > timeout)
            .collect();
        for h in expired {
            out.push(Output::Answer {
                id: h.id,
                answer: Err(format!(
                    "the cut tagged {} did not reach this leader within {timeout:?}",
                    h.tag
                )),
            });
        }
    }
}
