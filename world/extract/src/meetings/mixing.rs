//! Detecting mixes (the property paper, Section 6: "we log a mixing event
//! whenever two targets get close to each other within some distance"): a pair of present targets *enters* contact when they
//! come within the mixing distance, and that moment is one `mix` event —
//! not every step they stay close. The pair leaves contact when they move
//! further apart than the release distance (≥ the mixing distance; a little
//! hysteresis so that two people hovering at the threshold do not produce a
//! mix per step), or when one of them leaves the scene; only then can they
//! mix again.

use crate::geometry::{NeighbourGrid, Vec2};
use serde::{Deserialize, Serialize};

/// A pair that came within the mixing distance this step, and how far
/// apart they were then.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Entering {
    pub a: u32,
    pub b: u32,
    /// Metres between the two at this step (≤ the mixing distance).
    pub distance: f64,
}

/// Remembers which pairs are in contact between steps. Its state (the
/// pairs in contact) serializes, so a live sensor can journal it.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct MixDetector {
    mix_distance: f64,
    release_distance: f64,
    /// Pairs (i < j) in contact after the last step, sorted.
    contact: Vec<(u32, u32)>,
    // Scratch, rebuilt every step.
    #[serde(skip)]
    next: Vec<(u32, u32)>,
    #[serde(skip)]
    close: Vec<(u32, u32, f64)>,
}

impl MixDetector {
    /// Panics unless 0 < `mix_distance` ≤ `release_distance` (finite).
    pub fn new(mix_distance: f64, release_distance: f64) -> Self {
        assert!(
            mix_distance.is_finite()
                && mix_distance > 0.0
                && release_distance.is_finite()
                && release_distance >= mix_distance,
            "need 0 < mix distance ({mix_distance}) <= release distance ({release_distance})"
        );
        MixDetector {
            mix_distance,
            release_distance,
            contact: Vec::new(),
            next: Vec::new(),
            close: Vec::new(),
        }
    }

    /// The largest radius this detector queries the grid with.
    pub fn reach(&self) -> f64 {
        self.release_distance
    }

    /// Updates contacts for a new step and appends to `entering` the pairs
    /// (i < j, ascending) that came within the mixing distance since the
    /// last step. `grid` must have been built over `positions` with a reach
    /// of at least [`MixDetector::reach`].
    pub fn step(
        &mut self,
        grid: &NeighbourGrid,
        positions: &[Option<Vec2>],
        entering: &mut Vec<(u32, u32)>,
    ) {
        self.step_with(grid, positions, |e| entering.push((e.a, e.b)));
    }

    /// [`MixDetector::step`], with the distance of each entering pair.
    pub(crate) fn step_measured(
        &mut self,
        grid: &NeighbourGrid,
        positions: &[Option<Vec2>],
        entering: &mut Vec<Entering>,
    ) {
        self.step_with(grid, positions, |e| entering.push(e));
    }

    fn step_with(
        &mut self,
        grid: &NeighbourGrid,
        positions: &[Option<Vec2>],
        mut enter: impl FnMut(Entering),
    ) {
        self.close.clear();
        grid.for_each_pair_within(positions, self.release_distance, |i, j, d| {
            self.close.push((i as u32, j as u32, d));
        });
        self.close.sort_unstable_by_key(|&(i, j, _)| (i, j));
        self.next.clear();
        for &(i, j, d) in &self.close {
            let was = self.contact.binary_search(&(i, j)).is_ok();
            if d <= self.mix_distance {
                if !was {
                    enter(Entering {
                        a: i,
                        b: j,
                        distance: d,
                    });
                }
                self.next.push((i, j));
            } else if was {
                self.next.push((i, j));
            }
        }
        std::mem::swap(&mut self.contact, &mut self.next);
    }

    /// Pairs currently in contact, sorted.
    #[cfg(test)]
    pub(crate) fn in_contact(&self) -> &[(u32, u32)] {
        &self.contact
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(detector: &mut MixDetector, positions: &[Option<Vec2>]) -> Vec<(u32, u32)> {
        let mut grid = NeighbourGrid::new();
        grid.rebuild(positions, detector.reach());
        let mut out = Vec::new();
        detector.step(&grid, positions, &mut out);
        out
    }

    #[test]
    fn one_mix_per_encounter_with_hysteresis() {
        let mut d = MixDetector::new(1.0, 1.5);
        let at = |x: f64| vec![Some(Vec2::new(0.0, 0.0)), Some(Vec2::new(x, 0.0)), None];
        assert!(run(&mut d, &at(3.0)).is_empty());
        assert_eq!(run(&mut d, &at(0.9)), vec![(0, 1)]);
        assert!(run(&mut d, &at(0.5)).is_empty());
        // Out past the mixing distance but inside the release distance and
        // back in: still the same encounter.
        assert!(run(&mut d, &at(1.3)).is_empty());
        assert!(run(&mut d, &at(0.8)).is_empty());
        // Released, then a new encounter.
        assert!(run(&mut d, &at(1.6)).is_empty());
        assert!(d.in_contact().is_empty());
        assert_eq!(run(&mut d, &at(1.0)), vec![(0, 1)]);
        // Leaving the scene ends contact too.
        assert!(run(&mut d, &[Some(Vec2::ZERO), None, None]).is_empty());
        assert_eq!(run(&mut d, &at(0.2)), vec![(0, 1)]);
    }

    #[test]
    fn several_pairs_in_order() {
        let mut d = MixDetector::new(1.0, 1.0);
        let positions = vec![
            Some(Vec2::new(0.0, 0.0)),
            Some(Vec2::new(10.0, 0.0)),
            Some(Vec2::new(0.5, 0.0)),
            Some(Vec2::new(10.5, 0.0)),
        ];
        assert_eq!(run(&mut d, &positions), vec![(0, 2), (1, 3)]);
    }
}
