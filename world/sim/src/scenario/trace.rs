//! What a scenario produces: the header facts of a trace and its events in
//! time order, plus the hidden ground truth needed to check it.

use super::identity::IdentityTrace;
use crate::events::{SimEvent, TimedEvent};
use idmesh_extract::Report;

/// The facts of the trace's `header` line.
#[derive(Debug, Clone, PartialEq)]
pub struct TraceHeader {
    /// n, the number of tracks.
    pub tracks: usize,
    /// k, the number of red targets.
    pub red: usize,
    /// The red tracks at time 0, if the scenario reveals them.
    pub initial_red: Option<Vec<u32>>,
    /// Free text: what produced the trace.
    pub source: String,
    /// Free text: the scenario's parameters.
    pub description: String,
}

/// A generated trace.
#[derive(Debug, Clone, PartialEq)]
pub struct GeneratedTrace {
    pub header: TraceHeader,
    /// In non-decreasing time order; within one time: mixes, observations,
    /// moves, then the truth.
    pub events: Vec<TimedEvent>,
    /// Ground truth at time 0 (whether or not the header reveals it).
    pub true_initial_red: Vec<u32>,
    /// Seconds of motion covered (the time of the last step).
    pub duration: f64,
    /// The identities and their reads, for a scenario with
    /// [`identities`](super::Scenario::identities) on.
    pub identity: Option<IdentityTrace>,
    /// What the simulated tracker reported, for a scenario with
    /// [`tracker_reports`](super::Scenario::tracker_reports) on: fed to
    /// `idmesh-extract`'s extractor with
    /// [`ExtractionParams::extractor_config`](crate::events::ExtractionParams::extractor_config),
    /// they give this trace's mixes and observations.
    pub reports: Option<Vec<Report>>,
}

/// Counts of a trace's events.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TraceStats {
    pub mixes: usize,
    pub observations: usize,
    pub moves: usize,
    pub truths: usize,
    /// Mixes among mix + observe events (0 when there are none).
    pub mix_share: f64,
    /// Mixes the tracker really got wrong (ground truth).
    pub exchanges: usize,
}

impl GeneratedTrace {
    pub fn stats(&self) -> TraceStats {
        let mut s = TraceStats {
            mixes: 0,
            observations: 0,
            moves: 0,
            truths: 0,
            mix_share: 0.0,
            exchanges: 0,
        };
        for e in &self.events {
            match e.event {
                SimEvent::Mix { exchanged, .. } => {
                    s.mixes += 1;
                    s.exchanges += exchanged as usize;
                }
                SimEvent::Observe { .. } => s.observations += 1,
                SimEvent::Move { .. } => s.moves += 1,
                SimEvent::Truth { .. } => s.truths += 1,
            }
        }
        let sensing = s.mixes + s.observations;
        if sensing > 0 {
            s.mix_share = s.mixes as f64 / sensing as f64;
        }
        s
    }

    /// The `mix` and `observe` events only, in order.
    #[cfg(test)]
    pub(crate) fn sensing_events(&self) -> impl Iterator<Item = &TimedEvent> {
        self.events.iter().filter(|e| e.event.is_sensing())
    }
}
