//! The leader's counters ([`LeaderStats`]): what it applied, sent,
//! received and refused, as the coordinator's `stats` query shows them.

use super::*;

impl Leader {
    /// Names the process running this leader (for its counters).
    pub(crate) fn set_host(&mut self, host: &str) {
        self.stats.host = host.to_string();
    }

    /// How long the last recovery (restart or adoption) took to catch up.
    pub(crate) fn note_recovered(&mut self, seconds: f64) {
        self.stats.recoveries += 1;
        self.stats.recovery_seconds = seconds;
    }

    /// Counts a damaged journal found at a restart, and the entries
    /// dropped with it (fetched again from the sensor and the peers).
    pub(crate) fn note_journal_damage(&mut self, dropped: u64) {
        self.stats.journal_damage += 1;
        self.stats.journal_dropped += dropped;
    }

    /// Counts a snapshot taken.
    pub(crate) fn note_snapshot(&mut self) {
        self.stats.snapshots += 1;
    }

    pub fn stats(&self) -> LeaderStats {
        let mut stats = self.stats.clone();
        stats.position = self.position;
        stats.stream_events = self.events;
        stats.stream_finished = self.finished;
        stats.quiet = self.is_quiet();
        stats.transfers_kept = self.sent.len() as u64;
        stats.fsyncs = idmesh_journal::fsyncs();
        if let Some(s) = &self.started {
            stats.coefficients = match &s.factored {
                Some(held) => held.coefficients() as u64,
                None => s.share.len() as u64,
            };
            stats.omp_runs = s.share.omp_runs();
            stats.tracks_owned = s.own.iter().filter(|&&o| o).count() as u64;
            stats.tracks_followed = s.interest.len() as u64;
            stats.rows_held = s.rows.as_ref().map_or(0, |r| r.len() as u64);
            stats.identity_repairs = s.trees.as_ref().map_or(0, |trees| trees.repairs());
            stats.belief_repairs = s.factored.as_ref().map_or(0, |held| {
                let belief = held.stats();
                belief.retried_splits + belief.repairs
            });
            // Starts kept for nobody are not the track's tree (yet).
            stats.tree_tracks = s.trees.as_ref().map_or(0, |trees| {
                trees
                    .held_tracks()
                    .filter(|t| !s.passive_trees.contains(t))
                    .count() as u64
            });
        }
        stats
    }

    /// Counts an input refused at the door; returns the count so far.
    pub fn note_rejected(&mut self) -> u64 {
        self.stats.rejected += 1;
        self.stats.rejected
    }

    /// Counts bytes of a snapshot sent to the role's standby.
    pub(crate) fn note_standby_sent(&mut self, bytes: usize) {
        self.stats.standby_bytes += bytes as u64;
    }

    /// Counts bytes the actor sent for this leader.
    pub(crate) fn note_sent(&mut self, bytes: usize) {
        self.stats.bytes_sent += bytes as u64;
    }
}
