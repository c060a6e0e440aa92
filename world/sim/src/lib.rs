//! # idmesh-sim — turning the world into events
//!
//! Simulated crowds, real trajectory replay, and the sensor model that
//! turns motion into trace lines. Pure and synchronous: no tokio, no Zenoh,
//! so the evaluation and the acoustic front end use it without the
//! runtime. The sensor process that streams events to the leaders is
//! `idmesh-sensor` (`sensor/`); the acoustic tracking front end is
//! `idmesh-acoustic` (`world/acoustic/`).
//!
//! The scenario generator follows the evaluation of Jiang et al. (TOSN 2013,
//! Section 6): targets move in a field, a `mix` is logged whenever two
//! targets come within a mixing distance, an `observe` whenever one target is
//! separated from all others by an observation distance, and the share of
//! mixing events is steered by these two distances.
//!
//! A map of the crate (private modules; what other crates use is
//! re-exported below, by concern):
//! - `geometry` — points, the rectangular field, a neighbour grid.
//! - `motion` — ground-truth motion: a social-force crowd, random
//!   waypoint, and replay of real pedestrian trajectories.
//! - `events` — from motion to events: the sensor model, the
//!   track-to-target assignment, mixing and observation detection.
//! - `scenario` — the [`Scenario`] builder that ties them together into a
//!   [`GeneratedTrace`], with progress reporting and trace output.
//!
//! ```
//! use idmesh_sim::{write_trace, Scenario};
//!
//! let trace = Scenario::crowd()
//!     .targets(20)       // n
//!     .red(10)           // k
//!     .duration(60.0)    // seconds of motion
//!     .mix_distance(1.0) // metres
//!     .swap(0.5)
//!     .seed(42)
//!     .generate_with_progress(&mut |done, total| assert!(done <= total))
//!     .unwrap();
//! let stats = trace.stats();
//! assert!(stats.mixes > 0 && stats.observations > 0);
//! let jsonl = write_trace(&trace, Vec::new(), "crowd.jsonl").unwrap();
//! assert!(jsonl.starts_with(br#"{"kind":"header""#));
//! ```

mod events;
mod geometry;
mod motion;
mod scenario;

// Points, the rectangular field, a neighbour grid.
pub use geometry::{NeighbourGrid, Rect, Vec2};
// Ground-truth motion: a social-force crowd, random waypoint, and the
// recorded pedestrians (their scenes, timing and data folder).
pub use motion::crowd::{CrowdParams, Goals};
pub use motion::pedestrians::{data_dir, Scene, SceneError, Timing};
pub use motion::waypoint::{Waypoint, WaypointParams};
pub use motion::Motion;
// From motion to events: the sensor model, mixing and observation.
pub use events::{ExtractionParams, MixDetector, SensorModel, SimEvent, TimedEvent};
// The scenario builder and what it generates.
pub use scenario::{
    GeneratedTrace, IdentityTrace, Model, Scenario, ScenarioError, SceneSource, TraceHeader,
    TraceStats,
};
// Trace output: a generated trace as lines, a file, tracker output.
pub use scenario::trace_out::{event_line, lines, write_trace, write_tracker_output};
