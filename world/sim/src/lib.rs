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
//! A map of the crate:
//! - [`geometry`] — points, the rectangular field, a neighbour grid.
//! - [`motion`] — ground-truth motion: a social-force crowd, random
//!   waypoint, and replay of real pedestrian trajectories.
//! - [`events`] — from motion to events: the sensor model, the
//!   track-to-target assignment, mixing and observation detection.
//! - [`scenario`] — the [`Scenario`] builder that ties them together into a
//!   [`GeneratedTrace`], with progress reporting and trace output.
//!
//! ```
//! use idmesh_sim::Scenario;
//! use idmesh_sim::scenario::trace_out::write_trace;
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

pub mod events;
pub mod geometry;
pub mod motion;
pub mod scenario;

pub use events::{SensorModel, SimEvent, TimedEvent};
pub use scenario::{GeneratedTrace, Length, Model, RedChoice, Scenario, ScenarioError};
