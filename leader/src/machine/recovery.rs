//! A leader coming back: rebuilt from its snapshot and journal, then
//! everything sent and received while it was down, again.

use super::{Node, Now, Output, Recovery, Timers};
use crate::door;
use crate::error::LeaderError;
use crate::journal::Kind;
use crate::state::Leader;

/// Who runs a role: the process, and the epoch it holds the role at (0
/// without voters; a plain process name means that).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Holder<'a> {
    pub process: &'a str,
    pub epoch: u64,
}

impl<'a> From<&'a str> for Holder<'a> {
    fn from(process: &'a str) -> Self {
        Holder { process, epoch: 0 }
    }
}

impl<'a> From<&'a String> for Holder<'a> {
    fn from(process: &'a String) -> Self {
        Holder::from(process.as_str())
    }
}

impl Node {
    /// The node of leader `name` (run by `holder`) as its durable state left
    /// it: `snapshot` (if any) with `entries` (the journal's inputs, in
    /// order) replayed. When there was anything to replay, or the role
    /// was `adopted` from a process gone for good, it then catches up:
    /// the outputs send again every transfer it sent (the receivers drop
    /// what they have), ask the sensor for every batch from the next one
    /// it expects, every peer for what it sent here since, and the sensor
    /// again for a follow still unanswered. Until all of them answered,
    /// queries are refused as "recovering".
    ///
    /// `damaged`: the journal was found damaged and cut before its damaged
    /// entry; this many entries were dropped (counted, and the leader
    /// catches up even with nothing left to replay: it was further on).
    #[allow(clippy::too_many_arguments)]
    pub fn recover<'a>(
        name: &str,
        holder: impl Into<Holder<'a>>,
        snapshot: Option<&[u8]>,
        entries: impl IntoIterator<Item = (Kind, &'a [u8])>,
        adopted: bool,
        damaged: Option<u64>,
        timers: Timers,
        now: Now,
    ) -> Result<(Node, Vec<Output>), LeaderError> {
        let mut leader = match snapshot {
            Some(bytes) => Leader::restore(bytes)?,
            None => Leader::new(name),
        };
        let holder = holder.into();
        leader.set_host(holder.process);
        leader.set_epoch(holder.epoch);
        if let Some(dropped) = damaged {
            leader.note_journal_damage(dropped);
        }
        let mut node = Node::new(leader, timers);
        // The snapshot's mark is safe whatever became of the journal.
        if snapshot.is_some() {
            node.safe = Some(node.leader.durable());
        }
        let mut replayed = 0;
        for (kind, bytes) in entries {
            replayed += 1;
            if kind == Kind::Rejected {
                // A refusal, journaled so the count survives restarts.
                node.leader.note_rejected();
                continue;
            }
            // Only admitted inputs are journaled: the door takes them
            // again (counted if not, as when they first came).
            let input = match door::admit(&node.leader, kind, bytes) {
                Ok(input) => input,
                Err(problem) => {
                    let rejected = node.leader.note_rejected();
                    tracing::warn!(leader = %name, what = ?kind, %problem, rejected, "journal entry rejected");
                    continue;
                }
            };
            if let Err(e) = door::apply(&mut node.leader, input, bytes.len()) {
                node.failure
                    .get_or_insert(format!("replaying the journal: {e}"));
            }
        }
        node.journaled = replayed;
        let mut out = Vec::new();
        let behind = adopted || damaged.is_some();
        if node.timers.journal && (snapshot.is_some() || replayed > 0 || behind) {
            tracing::info!(leader = %name, snapshot = snapshot.is_some(), entries = replayed,
                dropped = damaged, position = node.leader.position(), "state recovered");
            node.catch_up(now, &mut out);
        }
        // A gap left by the journal, a snapshot due: as after any input.
        node.after_input(now, &mut out);
        node.send_outgoing(&mut out);
        Ok((node, out))
    }

    /// After a restart: everything sent and received while down, again.
    fn catch_up(&mut self, now: Now, out: &mut Vec<Output>) {
        for (to, transfer) in self.leader.all_sent().to_vec() {
            self.send(to, transfer);
        }
        self.ask_resend(now, out);
        let name = self.leader.name().to_string();
        let peers: Vec<String> = self
            .leader
            .leaders()
            .iter()
            .filter(|p| **p != name)
            .cloned()
            .collect();
        for peer in &peers {
            self.ask_transfers(now, peer, out);
        }
        self.ask_follow(out);
        self.recovery = Some(Recovery {
            since: now,
            batches: false,
            peers,
        });
        tracing::info!(leader = %name, next_batch = self.leader.next_batch(),
            position = self.leader.position(), "catching up");
    }
}
