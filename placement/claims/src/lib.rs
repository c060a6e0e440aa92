//! A process's word with the voters: who holds each role (a leader role,
//! a sensor), at which epoch, decided by consensus (`idmesh-consensus`)
//! rather than by a lock on a shared disk. The leader processes and the
//! sensor's standby both claim through it; it sits below the roles so
//! that neither depends on the other's crate.
//!
//! With `[[voter]]`s in the topology a process runs a role only once the
//! voters have committed its claim: its own role at start (or back from a
//! standby), another's after the role's token has been gone for the
//! takeover time, naming the epoch it fences off so that two adopters
//! racing for one loss cannot both win. The role then runs at the epoch
//! the claim won, stamped on every message it sends, and receivers refuse
//! any older one (`idmesh_protocol::wire::epoch`): that is what stops a
//! former holder that was only cut off.
//!
//! The lease: a holder reads the map at every sweep. It stops a role the
//! map gives to someone else (it was superseded while cut off), and
//! every role it holds when no voter has led for [`Claims::lease`] (it
//! cannot know it still holds them; a successor may be running). Answers
//! are then `degraded`, naming the missing roles, until a majority of
//! voters is back and the roles are claimed again: nothing is lost, since
//! every role comes back from its journal or its standby's copy.

use idmesh_consensus::{Command, RoleEntry, RolesAnswer};
use idmesh_protocol::wire::keys::Keys;
use std::time::{Duration, Instant};
use zenoh::query::{ConsolidationMode, QueryTarget};
use zenoh::Session;

/// How a claim ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Claimed {
    /// The role is this process's, at this epoch.
    Won(u64),
    /// Another process holds it (it won the race, or never lost it).
    Lost { holder: String, epoch: u64 },
    /// No voter led within the time given: nothing was decided.
    Undecided,
}

/// What the map says of a role this process runs at `epoch`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Verdict {
    /// Still this process's, at its epoch.
    Holds,
    /// Taken over (or released) since: stop running it.
    Superseded { holder: Option<String>, epoch: u64 },
}

/// The verdict on `role`, run here (`me`) at `epoch`, by `map`.
pub fn verdict(map: &RolesAnswer, role: &str, me: &str, epoch: u64) -> Verdict {
    match map.get(role) {
        Some(e) if e.holder.as_deref() == Some(me) && e.epoch == epoch => Verdict::Holds,
        Some(e) => Verdict::Superseded {
            holder: e.holder.clone(),
            epoch: e.epoch,
        },
        // Never claimed: only a process that did not claim runs it (a
        // restart at epoch 0 before the voters answered).
        None => Verdict::Superseded {
            holder: None,
            epoch: 0,
        },
    }
}

/// The epoch a takeover of `role` must name: that of its holder in `map`,
/// None when nobody holds it (never claimed, or released).
pub fn fencing(map: &RolesAnswer, role: &str) -> Option<u64> {
    map.get(role)
        .filter(|e| e.holder.is_some())
        .map(|e| e.epoch)
}

/// What the map's entry of a role (`entry`) says of a claim of it by
/// `me` fencing off `fencing`: won, lost, or not decided yet (propose
/// again). [`Claims::claim`] decides by it, and so does the simulator.
pub fn claim_decision(
    entry: Option<&RoleEntry>,
    me: &str,
    fencing: Option<u64>,
) -> Option<Claimed> {
    match entry {
        Some(e) if e.holder.as_deref() == Some(me) => Some(Claimed::Won(e.epoch)),
        // Someone else holds it at an epoch past the one this claim
        // fences off: it won, or never lost it.
        Some(e) if e.holder.is_some() && Some(e.epoch) != fencing => Some(Claimed::Lost {
            holder: e.holder.clone().unwrap_or_default(),
            epoch: e.epoch,
        }),
        // Released past the epoch this claim names: it moved on without
        // what the claimant holds.
        Some(e) if fencing.is_some_and(|f| f != e.epoch) => Some(Claimed::Lost {
            holder: "nobody (released)".to_string(),
            epoch: e.epoch,
        }),
        _ => None,
    }
}

/// What the map's entry of a role says of `me` moving it past epoch
/// `from` ([`Claims::advance`]): won at the new epoch, lost to another
/// holder, or not decided yet.
pub fn advance_decision(entry: Option<&RoleEntry>, me: &str, from: u64) -> Option<Claimed> {
    match entry {
        Some(e) if e.holder.as_deref() == Some(me) && e.epoch > from => Some(Claimed::Won(e.epoch)),
        Some(e) if e.holder.as_deref() != Some(me) => Some(Claimed::Lost {
            holder: e.holder.clone().unwrap_or_default(),
            epoch: e.epoch,
        }),
        _ => None,
    }
}

/// The voters as one process sees them.
pub struct Claims {
    session: Session,
    keys: Keys,
    me: String,
    /// How long the map may go unread before the roles here stop.
    pub lease: Duration,
    /// The newest map read, and when.
    last: Option<(RolesAnswer, Instant)>,
}

impl Claims {
    pub fn new(session: Session, keys: Keys, me: &str, lease: Duration) -> Self {
        Claims {
            session,
            keys,
            me: me.to_string(),
            lease,
            last: None,
        }
    }

    /// Reads the map from the voters now: the leading voter's (None if no
    /// voter leads or none answered).
    pub async fn read(&mut self) -> Option<&RolesAnswer> {
        let asked = Instant::now();
        let replies = self
            .session
            .get(self.keys.query_roles())
            // Every voter's answer, not one: they share a key, which
            // Zenoh's default consolidation keeps one reply of.
            .target(QueryTarget::All)
            .consolidation(ConsolidationMode::None)
            .timeout(Duration::from_millis(500))
            .await
            .ok()?;
        let mut answers = Vec::new();
        while let Ok(reply) = replies.recv_async().await {
            let Ok(sample) = reply.result() else { continue };
            match serde_json::from_slice::<RolesAnswer>(&sample.payload().to_bytes()) {
                Ok(answer) => answers.push(answer),
                Err(e) => tracing::warn!(error = %e, "a voter's map that does not read"),
            }
        }
        let heard = answers.len();
        let newest = RolesAnswer::newest(answers);
        if newest.is_none() {
            tracing::debug!(process = %self.me, heard, seconds = asked.elapsed().as_secs_f64(), "no leading voter answered");
        }
        let newest = newest?;
        self.last = Some((newest, Instant::now()));
        self.last.as_ref().map(|(map, _)| map)
    }

    /// The epoch of `role` in the map last read (0: never claimed, or no
    /// map read yet).
    pub fn last_epoch(&self, role: &str) -> u64 {
        self.last
            .as_ref()
            .and_then(|(map, _)| map.get(role))
            .map_or(0, |e| e.epoch)
    }

    /// Whether the map has gone unread longer than the lease (never read
    /// counts from `since`, when the roles were first run).
    pub fn lapsed(&self, since: Instant) -> bool {
        let read = self.last.as_ref().map_or(since, |(_, at)| *at);
        read.elapsed() > self.lease
    }

    /// Claims `role` for this process, fencing off `fencing` (the epoch of
    /// the holder it replaces; None if it believes the role unheld), and
    /// waits until the map shows who won, or until `patience` runs out.
    /// A proposal lost (no leader, or a leader change) is made again.
    pub async fn claim(&mut self, role: &str, fencing: Option<u64>, patience: Duration) -> Claimed {
        let command = Command::Claim {
            role: role.to_string(),
            holder: self.me.clone(),
            fencing,
        };
        let me = self.me.clone();
        self.decide(&command, role, patience, |e| {
            claim_decision(e, &me, fencing)
        })
        .await
    }

    /// Moves `role`, held here at epoch `from`, to the next epoch
    /// (`Command::Advance`): every claim naming `from` loses from then on.
    /// Waits until the map shows the role here past `from` (won, at the
    /// new epoch), held by another (lost), or `patience` runs out.
    pub async fn advance(&mut self, role: &str, from: u64, patience: Duration) -> Claimed {
        let command = Command::Advance {
            role: role.to_string(),
            holder: self.me.clone(),
            from,
        };
        let me = self.me.clone();
        self.decide(&command, role, patience, |e| advance_decision(e, &me, from))
            .await
    }

    /// Proposes `command` until the map's entry of `role` decides it
    /// (`decided`), or `patience` runs out. A proposal lost (no leader, or
    /// a leader change) is made again.
    async fn decide(
        &mut self,
        command: &Command,
        role: &str,
        patience: Duration,
        decided: impl Fn(Option<&RoleEntry>) -> Option<Claimed>,
    ) -> Claimed {
        let deadline = Instant::now() + patience;
        let mut wait = Duration::from_millis(100);
        while Instant::now() < deadline {
            self.propose(command).await;
            tokio::time::sleep(wait).await;
            wait = (wait * 2).min(Duration::from_secs(1));
            let Some(map) = self.read().await else {
                continue;
            };
            if let Some(outcome) = decided(map.get(role)) {
                return outcome;
            }
        }
        Claimed::Undecided
    }

    /// Gives `role` up (its actor has stopped: handed home, or this
    /// process is stopping). Fire and forget: a release lost leaves the
    /// role to be taken over by fencing, as after a loss.
    pub async fn release(&self, role: &str) {
        let command = Command::Release {
            role: role.to_string(),
            holder: self.me.clone(),
        };
        self.propose(&command).await;
    }

    async fn propose(&self, command: &Command) {
        let Ok(bytes) = postcard::to_allocvec(command) else {
            return;
        };
        if let Err(e) = self.session.put(self.keys.raft_propose(), bytes).await {
            tracing::debug!(error = %e, "a claim was not sent");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn map(entries: &[(&str, Option<&str>, u64)]) -> RolesAnswer {
        RolesAnswer {
            voter: 1,
            leader: 1,
            term: 3,
            roles: entries
                .iter()
                .map(|(role, holder, epoch)| RoleEntry {
                    role: role.to_string(),
                    holder: holder.map(str::to_string),
                    epoch: *epoch,
                })
                .collect(),
        }
    }

    /// A claim is won once the map names its claimant, lost once it names
    /// another past the fenced epoch (or nobody, released past it), and
    /// undecided while the fenced holding stands: proposed again.
    #[test]
    fn a_claim_is_decided_only_by_a_map_past_the_epoch_it_fences() {
        let m = map(&[
            ("l1", Some("p1"), 2),
            ("l2", Some("p2"), 5),
            ("l3", None, 4),
        ]);
        assert_eq!(
            claim_decision(m.get("l1"), "p1", Some(1)),
            Some(Claimed::Won(2))
        );
        assert_eq!(claim_decision(m.get("l2"), "p1", Some(5)), None);
        assert_eq!(
            claim_decision(m.get("l2"), "p1", Some(4)),
            Some(Claimed::Lost {
                holder: "p2".into(),
                epoch: 5
            })
        );
        assert!(matches!(
            claim_decision(m.get("l3"), "p1", Some(3)),
            Some(Claimed::Lost { epoch: 4, .. })
        ));
        assert_eq!(claim_decision(m.get("l3"), "p1", Some(4)), None);
        assert_eq!(claim_decision(None, "p1", None), None);
        // An advance from epoch 2 is won only past it.
        assert_eq!(advance_decision(m.get("l1"), "p1", 2), None);
        assert_eq!(
            advance_decision(m.get("l1"), "p1", 1),
            Some(Claimed::Won(2))
        );
        assert!(matches!(
            advance_decision(m.get("l2"), "p1", 5),
            Some(Claimed::Lost { epoch: 5, .. })
        ));
    }

    #[test]
    fn a_holder_keeps_its_role_only_at_its_own_epoch() {
        let m = map(&[("l1", Some("p1"), 2), ("l2", None, 4)]);
        assert_eq!(verdict(&m, "l1", "p1", 2), Verdict::Holds);
        // Taken over while cut off, and given back since: not the same
        // holding, the former epoch is fenced.
        assert_eq!(
            verdict(&m, "l1", "p1", 1),
            Verdict::Superseded {
                holder: Some("p1".into()),
                epoch: 2
            }
        );
        assert_eq!(
            verdict(&m, "l1", "p2", 2),
            Verdict::Superseded {
                holder: Some("p1".into()),
                epoch: 2
            }
        );
        assert!(matches!(
            verdict(&m, "l2", "p2", 4),
            Verdict::Superseded { holder: None, .. }
        ));
        assert!(matches!(
            verdict(&m, "l9", "p9", 0),
            Verdict::Superseded { .. }
        ));
    }

    #[test]
    fn a_takeover_fences_off_the_holders_epoch_and_a_free_role_none() {
        let m = map(&[("l1", Some("p1"), 2), ("l2", None, 4)]);
        assert_eq!(fencing(&m, "l1"), Some(2));
        assert_eq!(fencing(&m, "l2"), None);
        assert_eq!(fencing(&m, "l3"), None);
    }

    #[test]
    fn the_map_to_trust_is_the_leading_voters_of_the_newest_term() {
        let answer = |voter, leader, term| RolesAnswer {
            voter,
            leader,
            term,
            roles: Vec::new(),
        };
        let chosen = RolesAnswer::newest([answer(1, 2, 5), answer(2, 2, 5), answer(3, 3, 4)]);
        assert_eq!(chosen.map(|a| (a.voter, a.term)), Some((2, 5)));
        assert_eq!(
            RolesAnswer::newest([answer(1, 0, 5), answer(2, 1, 5)]),
            None
        );
    }
}
