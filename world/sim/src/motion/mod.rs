//! Ground-truth motion: where every target is at every simulation step.
//!
//! The paper's evaluation (Jiang et al., Section 6) extracts its events from
//! a simulated crowd of up to 100 red or blue targets walking in an outdoor
//! market. A [`Motion`] is such a source of positions, advanced in fixed
//! time steps; the event extractor (`crate::events`) never looks inside it.
//!
//! - [`crowd`] — a Helbing–Molnár social-force crowd in a rectangular field:
//!   dense, interacting motion like the paper's market.
//! - [`waypoint`] — the random-waypoint model with pauses: independent,
//!   non-interacting targets, a classic networking baseline.
//! - [`pedestrians`] — replay of real annotated trajectories (the ETH/UCY
//!   scenes in `shared/data/pedestrians`), where people come and go.
//!
//! Every model is deterministic: the synthetic ones draw only from the
//! `ChaCha8Rng` they are given, the replay draws nothing.

pub(crate) mod crowd;
pub(crate) mod pedestrians;
pub(crate) mod waypoint;

use crate::geometry::Vec2;

/// A source of ground-truth positions for a fixed set of targets, advanced
/// in steps of [`Motion::dt`] seconds. Target `i` keeps its index for the
/// whole run; a target that is not in the scene at the current step (a
/// pedestrian before arriving or after leaving) has position `None`.
pub trait Motion {
    /// Number of targets (present or not).
    fn targets(&self) -> usize;

    /// Length of one step, seconds.
    fn dt(&self) -> f64;

    /// Index of the current step (0 before the first call to `advance`).
    fn step_index(&self) -> u64;

    /// Time of the current step, seconds from the start of the run.
    fn time(&self) -> f64 {
        self.step_index() as f64 * self.dt()
    }

    /// Positions at the current step, indexed by target; `None` = absent.
    fn positions(&self) -> &[Option<Vec2>];

    /// The number of steps the motion can make, if it is bounded (a replay
    /// ends with its recording); `None` = unbounded.
    fn max_steps(&self) -> Option<u64> {
        None
    }

    /// Moves every target forward by one step. Returns `false` (and leaves
    /// the state alone) when the motion has ended.
    fn advance(&mut self) -> bool;
}
