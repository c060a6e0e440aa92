//! The choices a [`super::Scenario`] is made of that are more than a number:
//! which motion model, how many targets are red, and how long to run.

use crate::motion::crowd::CrowdParams;
use crate::motion::pedestrians::{Scene, Timing};
use crate::motion::waypoint::WaypointParams;
use std::path::PathBuf;
use std::sync::Arc;

/// Where the ground-truth motion comes from.
#[derive(Debug, Clone)]
pub enum Model {
    /// The social-force crowd (`crate::motion::crowd`).
    Crowd(CrowdParams),
    /// Random waypoint with pauses (`crate::motion::waypoint`).
    Waypoint(WaypointParams),
    /// Replay of a real scene (`crate::motion::pedestrians`), from `start`
    /// seconds after its first annotation.
    Pedestrians { scene: SceneSource, start: f64 },
}

impl Model {
    pub(crate) fn name(&self) -> &'static str {
        match self {
            Model::Crowd(_) => "crowd",
            Model::Waypoint(_) => "waypoint",
            Model::Pedestrians { .. } => "pedestrians",
        }
    }
}

/// A pedestrian scene to replay: a file to load, or one already loaded
/// (to share one parse between many scenarios).
#[derive(Debug, Clone)]
pub enum SceneSource {
    File { path: PathBuf, timing: Timing },
    Loaded(Arc<Scene>),
}

/// Which targets are red.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub(crate) enum RedChoice {
    /// k = ⌊n/2⌋ targets drawn by the seed (the paper's "half of them are
    /// red").
    #[default]
    Half,
    /// k targets drawn by the seed.
    Count(usize),
    /// Exactly these tracks are red at time 0 (only the tests choose them).
    #[cfg(test)]
    Tracks(Vec<u32>),
}

/// When a run stops.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Length {
    /// After this many seconds of motion.
    Duration(f64),
    /// After this many `mix` + `observe` events; an error if the motion
    /// does not produce them within `within` seconds (or before a replay
    /// ends).
    Events { count: usize, within: f64 },
}
