//! Identity traces: every target carries a distinct identity (an RFID tag)
//! and readers now and then read it — the setting of Shin et al., *Lazy
//! Inference on Object Identities in Wireless Sensor Networks* (IPSN 2005),
//! whose lab experiment used RFID readers beside laser trackers.
//!
//! Turned on with [`Scenario::identities`](super::Scenario::identities).
//! The motion, the mixes, the colour observations, the moves and the red
//! truth are exactly those of the same scenario without identities (the
//! identity draws come from their own random streams); the trace gains:
//!
//! - a header with `identities` = n and, unless hidden
//!   ([`Scenario::reveal_initial_identity`](super::Scenario::reveal_initial_identity)),
//!   `initial_identity` (the identity on every track at time 0);
//! - `identify` lines from the reader model below;
//! - an `identity` array on every `truth` line.
//!
//! ## The reader model
//! Target i carries identity `target_identity[i]`, a permutation of 0..n
//! drawn by the seed (stream 5). A reader sees a target exactly when the
//! colour sensor could: when the target is present and *isolated* — no
//! other present target within the observation distance — at most once per
//! observation interval (its own [`ObservationScheduler`] with the
//! scenario's distance and interval, so reads and colour looks are
//! scheduled alike but independently). A read (stream 6) returns the true
//! identity with probability `accuracy` (default 0.9, the paper's) and
//! otherwise one of the n − 1 other identities, each equally likely: the
//! read model of the trace spec, so the filters' likelihoods are the
//! generator's. It is written on the track that follows the target after
//! the step's mixes; within a step the order is moves, mixes, observations,
//! reads, truth. Reads do not count towards
//! [`Scenario::events`](super::Scenario::events), which counts `mix` and
//! `observe` events.

use crate::events::{Assignment, ExtractionParams, ObservationScheduler};
use crate::geometry::{NeighbourGrid, Vec2};
use rand::seq::SliceRandom;
use rand::Rng;
use rand_chacha::ChaCha8Rng;

/// The paper's read accuracy: P(read = true identity).
pub(crate) const DEFAULT_IDENTITY_ACCURACY: f64 = 0.9;

/// The identity options of a scenario.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct IdentityOptions {
    /// Whether the scenario writes an identity trace at all.
    pub enabled: bool,
    /// P(a read returns the true identity), in (0, 1].
    pub accuracy: f64,
    /// Whether the header carries `initial_identity`.
    pub reveal_initial: bool,
}

impl Default for IdentityOptions {
    /// Off; accuracy 0.9; the initial identities revealed.
    fn default() -> Self {
        IdentityOptions {
            enabled: false,
            accuracy: DEFAULT_IDENTITY_ACCURACY,
            reveal_initial: true,
        }
    }
}

impl IdentityOptions {
    /// Checks the accuracy; returns what is wrong.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.accuracy > 0.0 && self.accuracy <= 1.0) {
            return Err(format!(
                "identity read accuracy must be in (0, 1], got {}",
                self.accuracy
            ));
        }
        Ok(())
    }
}

/// One read of a target's identity.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IdentityRead {
    pub time: f64,
    /// The track that follows the target read.
    pub track: u32,
    /// The identity read.
    pub identity: u32,
    /// Ground truth: the target read (not written to the trace).
    pub target: u32,
    /// Ground truth: whether the read is the target's identity.
    pub correct: bool,
}

/// The identity part of a generated trace.
#[derive(Debug, Clone, PartialEq)]
pub struct IdentityTrace {
    /// The accuracy every read was made with (written on each line).
    pub accuracy: f64,
    /// `target_identity[i]` = identity of target i.
    pub target_identity: Vec<u32>,
    /// `initial[t]` = identity on track t at time 0 (track t starts on
    /// target t, so this equals `target_identity`).
    pub initial: Vec<u32>,
    /// Whether the header carries `initial`.
    pub reveal_initial: bool,
    /// Every read, in time order.
    pub reads: Vec<IdentityRead>,
}

impl IdentityTrace {
    /// How many reads returned the true identity.
    #[cfg(test)]
    pub(crate) fn correct_reads(&self) -> usize {
        self.reads.iter().filter(|r| r.correct).count()
    }
}

/// The RFID reader model of the module docs, stepped with the motion.
#[derive(Debug, Clone)]
pub(crate) struct IdentityReader {
    accuracy: f64,
    target_identity: Vec<u32>,
    scheduler: ObservationScheduler,
    grid: NeighbourGrid,
    reach: f64,
    read_rng: ChaCha8Rng,
    due: Vec<u32>,
    reads: Vec<IdentityRead>,
}

impl IdentityReader {
    /// A reader for `n` targets: identities drawn from `identity_rng`, reads
    /// from `read_rng`, isolation and rate from `params`. Panics on an
    /// invalid accuracy or parameters (the scenario builder checks them).
    pub(crate) fn new(
        options: &IdentityOptions,
        params: &ExtractionParams,
        n: usize,
        mut identity_rng: ChaCha8Rng,
        read_rng: ChaCha8Rng,
    ) -> Self {
        if let Err(e) = options.validate() {
            panic!("{e}");
        }
        let mut target_identity: Vec<u32> = (0..n as u32).collect();
        target_identity.shuffle(&mut identity_rng);
        IdentityReader {
            accuracy: options.accuracy,
            target_identity,
            scheduler: ObservationScheduler::new(
                n,
                params.observe_distance,
                params.observe_interval,
            ),
            grid: NeighbourGrid::new(),
            reach: params.observe_distance,
            read_rng,
            due: Vec::new(),
            reads: Vec::new(),
        }
    }

    /// Reads every isolated target that is due at `time`; `assignment` says
    /// which track follows which target (after this step's mixes). Returns
    /// how many reads it made.
    pub(crate) fn step(
        &mut self,
        time: f64,
        positions: &[Option<Vec2>],
        assignment: &Assignment,
    ) -> usize {
        debug_assert_eq!(positions.len(), self.target_identity.len());
        self.grid.rebuild(positions, self.reach);
        self.due.clear();
        self.scheduler
            .step(time, &self.grid, positions, &mut self.due);
        let n = self.target_identity.len() as u32;
        for &i in &self.due {
            let truth = self.target_identity[i as usize];
            let correct = n == 1 || self.read_rng.gen::<f64>() < self.accuracy;
            let identity = if correct {
                truth
            } else {
                // One of the n − 1 other identities, each equally likely.
                let k = self.read_rng.gen_range(0..n - 1);
                if k >= truth {
                    k + 1
                } else {
                    k
                }
            };
            self.reads.push(IdentityRead {
                time,
                track: assignment.track_of(i as usize),
                identity,
                target: i,
                correct,
            });
        }
        self.due.len()
    }

    /// The identity part of the trace; `reveal_initial` says whether the
    /// header shows the identities at time 0.
    pub(crate) fn finish(self, reveal_initial: bool) -> IdentityTrace {
        IdentityTrace {
            accuracy: self.accuracy,
            // Track t follows target t at time 0.
            initial: self.target_identity.clone(),
            target_identity: self.target_identity,
            reveal_initial,
            reads: self.reads,
        }
    }
}
