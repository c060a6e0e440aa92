//! The sensing of one frame of positions: which pairs start a meeting and
//! which tracks are isolated and due for a look (the property paper's
//! Section 6 rules). Both the [`Extractor`](crate::Extractor), fed by a
//! tracker, and the simulator, fed by its motion models, run exactly this,
//! so a simulated trace and an extracted one detect the same meetings on
//! the same positions.

use crate::geometry::{NeighbourGrid, Vec2};
use crate::meetings::{Entering, MixDetector};
use crate::observing::ObservationScheduler;
use serde::{Deserialize, Serialize};

/// Mix and observation detection over successive frames of `n` slots
/// (targets or tracks); `None` in a frame is a slot absent from it.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct FrameSensing {
    mixes: MixDetector,
    observations: ObservationScheduler,
    // Scratch: rebuilt every frame.
    #[serde(skip)]
    grid: NeighbourGrid,
}

impl FrameSensing {
    /// Two slots closer than `mix_distance` meet, and meet again only
    /// after parting beyond `release_distance`; a slot with nobody within
    /// `observe_distance` is isolated, and looked at no more often than
    /// every `observe_interval` seconds. Panics on distances that are not
    /// positive and finite, or a release distance below the mixing one.
    pub fn new(
        slots: usize,
        mix_distance: f64,
        release_distance: f64,
        observe_distance: f64,
        observe_interval: f64,
    ) -> Self {
        FrameSensing {
            mixes: MixDetector::new(mix_distance, release_distance),
            observations: ObservationScheduler::new(slots, observe_distance, observe_interval),
            grid: NeighbourGrid::new(),
        }
    }

    /// Senses the frame at `time`: appends the pairs that start a meeting
    /// (ascending) to `entering` and the slots that are isolated, due and
    /// `eligible` (ascending) to `due`.
    pub fn sense(
        &mut self,
        time: f64,
        positions: &[Option<Vec2>],
        eligible: impl Fn(usize) -> bool,
        entering: &mut Vec<Entering>,
        due: &mut Vec<u32>,
    ) {
        let reach = self.mixes.reach().max(self.observations.reach());
        self.grid.rebuild(positions, reach);
        self.mixes.step_measured(&self.grid, positions, entering);
        self.observations
            .step_eligible(time, &self.grid, positions, eligible, due);
    }
}
