//! Several sensors, no single sequencer (docs/design/architecture.md, "Several
//! sensors").
//!
//! Each sensor of a deployment with several takes its producers' events
//! into its own [`intake`], at positions (time, producer, counter) that
//! only grow, and every sensor merges every intake into one order
//! ([`merge`]). The merged stream is the same at every sensor, so each
//! routes it through the same router — the same seqs, owners, interests
//! and mixing logs — and sends the batches of the leaders it serves. A cut
//! the coordinator asks for is an intake entry too: merged at one point of
//! the order everywhere, it is placed at the same seq by every sensor.
//!
//! [`Mesh`] is the part of a gateway's state this adds; the gateway's
//! journal records what changed it (peers' slices, ticks, cuts asked), so
//! a restarted sensor merges the same order again.

pub(crate) mod intake;
pub(crate) mod merge;
#[cfg(test)]
mod simulation;
#[cfg(test)]
mod tests;

use super::cuts::Cuts;
use idmesh_protocol::wire::coordinator_to_sensor::CutPlaced;
use idmesh_protocol::wire::sensor_to_sensor::{Entry, IntakeSlice, Position};
use intake::Intake;
use merge::Merge;
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;

/// Cuts remembered after they were placed or refused, for a request that
/// comes after a peer's entry with its tag was merged.
const RECENT_CUTS: usize = 1024;

/// Which sensors there are, which this is, and which leaders it feeds.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MeshConfig {
    /// Every sensor, in the topology's order.
    pub sensors: Vec<String>,
    /// This sensor's index among them.
    pub me: usize,
    /// Per leader (the stream's order): whether this sensor sends it its
    /// batches.
    pub serves: Vec<bool>,
}

#[derive(Debug, Serialize, Deserialize)]
pub(crate) struct Mesh {
    me: usize,
    serves: Vec<bool>,
    pub intake: Intake,
    pub merge: Merge,
    /// Cuts merged that wait for their event count; the "query" is the
    /// tag (the driver's queries wait in the gateway).
    pub cuts: Cuts<u64>,
    /// The stream's end has been routed (every sensor finished and all
    /// merged).
    pub ended: bool,
    /// Events this sensor took itself.
    taken_events: u64,
    recent: VecDeque<(u64, Result<CutPlaced, String>)>,
}

impl Mesh {
    pub(crate) fn new(config: &MeshConfig) -> Self {
        let peers: Vec<String> = config
            .sensors
            .iter()
            .enumerate()
            .filter(|&(i, _)| i != config.me)
            .map(|(_, s)| s.clone())
            .collect();
        Mesh {
            me: config.me,
            serves: config.serves.clone(),
            intake: Intake::new(&peers),
            merge: Merge::new(&config.sensors),
            cuts: Cuts::default(),
            ended: false,
            taken_events: 0,
            recent: VecDeque::new(),
        }
    }

    /// This sensor's name.
    pub(crate) fn name(&self) -> &str {
        &self.merge.sensors()[self.me]
    }

    /// The other sensors, each with the entry to fetch it from next and
    /// what is known of its watermark.
    pub(crate) fn peers(&self) -> Vec<(String, u64, Position, bool)> {
        (0..self.merge.sensors().len())
            .filter(|&i| i != self.me)
            .map(|i| {
                let (watermark, finished) = self.merge.known(i);
                (
                    self.merge.sensors()[i].clone(),
                    self.merge.received(i),
                    watermark.clone(),
                    finished,
                )
            })
            .collect()
    }

    /// Whether this sensor sends leader `i` its batches.
    pub(crate) fn serves(&self, i: usize) -> bool {
        self.serves.get(i).copied().unwrap_or(false)
    }

    /// Takes an event of its own (one [`Intake::refuses`] passed) and hands
    /// it to the merge.
    pub fn take(&mut self, position: Position, line: String) {
        self.intake.take(position.clone(), line.clone());
        self.taken_events += 1;
        self.own(vec![(position, Entry::Line(line))]);
    }

    /// Events this sensor took itself: an answer whose watermark for it
    /// is at least this includes them all.
    pub(crate) fn taken_events(&self) -> u64 {
        self.taken_events
    }

    /// Takes a cut asked of this sensor.
    pub(crate) fn cut(&mut self, tag: u64, rows: bool, events: Option<u64>) {
        let name = self.name().to_string();
        let position = self.intake.cut(&name, tag, rows, events);
        self.own(vec![(position, Entry::Cut { tag, rows, events })]);
    }

    /// A producer says nothing comes before `time`.
    pub(crate) fn tick(&mut self, time: f64) -> bool {
        let moved = self.intake.tick(time);
        self.own(Vec::new());
        moved
    }

    /// The producers say no more events come.
    pub(crate) fn finish(&mut self) {
        self.intake.finish();
        self.own(Vec::new());
    }

    /// A peer's slice of its intake.
    pub(crate) fn peer(&mut self, slice: IntakeSlice) -> Result<bool, String> {
        let i = self
            .merge
            .index(&slice.sensor)
            .filter(|&i| i != self.me)
            .ok_or_else(|| {
                format!(
                    "{:?} is not another sensor of this deployment",
                    slice.sensor
                )
            })?;
        self.merge.receive(
            i,
            slice.from,
            slice.entries,
            slice.watermark,
            slice.finished,
        )
    }

    /// A slice of this sensor's intake for peer `peer` (whose watermark is
    /// `above`), and whether the request changed this sensor (what to
    /// journal: [`Intake::slice`]).
    pub(crate) fn slice(
        &mut self,
        peer: &str,
        from: u64,
        above: &Position,
    ) -> Result<(IntakeSlice, bool), String> {
        let name = self.name().to_string();
        let (slice, changed) = self.intake.slice(&name, peer, from, above)?;
        if changed {
            self.own(Vec::new());
        }
        Ok((slice, changed))
    }

    /// Own entries (and the intake's watermark) to the merge.
    fn own(&mut self, entries: Vec<(Position, Entry)>) {
        let from = self.merge.received(self.me);
        let watermark = self.intake.watermark().clone();
        let finished = self.intake.finished();
        // Own entries come in order, numbered as taken.
        let _ = self
            .merge
            .receive(self.me, from, entries, watermark, finished);
    }

    /// The outcome of the cut tagged `tag`, if it was placed or refused
    /// lately.
    pub(crate) fn recalled(&self, tag: u64) -> Option<&Result<CutPlaced, String>> {
        self.recent.iter().find(|(t, _)| *t == tag).map(|(_, r)| r)
    }

    /// Remembers how the cut tagged `tag` ended.
    pub(crate) fn remember(&mut self, tag: u64, outcome: Result<CutPlaced, String>) {
        if self.recent.len() >= RECENT_CUTS {
            self.recent.pop_front();
        }
        self.recent.push_back((tag, outcome));
    }

    /// Whether a cut tagged `tag` was merged already (placed, refused, or
    /// waiting for its event count).
    pub(crate) fn merged_cut(&self, tag: u64) -> bool {
        self.recalled(tag).is_some() || self.cuts.holds(tag)
    }

    /// Events merged from each sensor, by name: what an answer includes.
    pub(crate) fn origins(&self) -> Vec<(String, u64)> {
        self.merge
            .sensors()
            .iter()
            .cloned()
            .zip(self.merge.merged().iter().copied())
            .collect()
    }
}
