//! Detecting observations (the property paper, Section 6: "an observation
//! event whenever one target is separated from all the other targets for
//! some distance"): a present target that no other present target
//! comes within the observation distance of is *isolated*, and a sensor can
//! see its colour without confusing it with someone else's. Each target is
//! looked at at most once per observation interval: an isolated target is
//! looked at as soon as its previous look is at least one interval old
//! (whether or not that look reported anything).

use crate::geometry::{NeighbourGrid, Vec2};
use serde::{Deserialize, Serialize};

/// Remembers when each target may be looked at next. Serializes (for a
/// sensor's journal); "any time" is `None`, since JSON has no infinities.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ObservationScheduler {
    observe_distance: f64,
    interval: f64,
    next_allowed: Vec<Option<f64>>,
}

impl ObservationScheduler {
    /// Panics unless `observe_distance` > 0 and `interval` ≥ 0 (finite).
    pub fn new(targets: usize, observe_distance: f64, interval: f64) -> Self {
        assert!(
            observe_distance.is_finite() && observe_distance > 0.0,
            "observation distance must be > 0, got {observe_distance}"
        );
        assert!(
            interval.is_finite() && interval >= 0.0,
            "observation interval must be >= 0, got {interval}"
        );
        ObservationScheduler {
            observe_distance,
            interval,
            next_allowed: vec![None; targets],
        }
    }

    /// The largest radius this scheduler queries the grid with.
    pub(crate) fn reach(&self) -> f64 {
        self.observe_distance
    }

    /// Appends to `due` (ascending) the targets that are isolated at `time`
    /// and may be looked at, and marks them as looked at. `grid` must have
    /// been built over `positions` with a reach of at least
    /// [`ObservationScheduler::reach`].
    pub fn step(
        &mut self,
        time: f64,
        grid: &NeighbourGrid,
        positions: &[Option<Vec2>],
        due: &mut Vec<u32>,
    ) {
        self.step_eligible(time, grid, positions, |_| true, due)
    }

    /// [`ObservationScheduler::step`] for the targets with `eligible(i)`
    /// only: a tracker's detection without class scores has nothing to
    /// observe, and must not use up the track's next look. The others
    /// still count as neighbours.
    pub(crate) fn step_eligible(
        &mut self,
        time: f64,
        grid: &NeighbourGrid,
        positions: &[Option<Vec2>],
        eligible: impl Fn(usize) -> bool,
        due: &mut Vec<u32>,
    ) {
        for (i, p) in positions.iter().enumerate() {
            let waiting = self.next_allowed[i].is_some_and(|next| time < next - 1e-9);
            if p.is_none() || waiting || !eligible(i) {
                continue;
            }
            let mut isolated = true;
            grid.for_each_neighbour(positions, i, self.observe_distance, |_, _| isolated = false);
            if isolated {
                self.next_allowed[i] = Some(time + self.interval);
                due.push(i as u32);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn isolated_targets_at_a_limited_rate() {
        let mut s = ObservationScheduler::new(3, 2.0, 1.0);
        let positions = vec![
            Some(Vec2::new(0.0, 0.0)),
            Some(Vec2::new(1.5, 0.0)),
            Some(Vec2::new(10.0, 0.0)),
        ];
        let mut grid = NeighbourGrid::new();
        grid.rebuild(&positions, s.reach());
        let mut due = Vec::new();
        s.step(0.0, &grid, &positions, &mut due);
        assert_eq!(due, vec![2]);
        due.clear();
        s.step(0.5, &grid, &positions, &mut due);
        assert!(due.is_empty());
        s.step(1.0, &grid, &positions, &mut due);
        assert_eq!(due, vec![2]);
        // Absent targets are never observed, and do not block others.
        let positions = vec![Some(Vec2::new(0.0, 0.0)), None, None];
        grid.rebuild(&positions, s.reach());
        due.clear();
        s.step(2.0, &grid, &positions, &mut due);
        assert_eq!(due, vec![0]);
    }
}
