//! # idmesh-sensor — turning the world into events
//!
//! Simulators, real trajectory replay, the acoustic tracking front end and
//! the sensor process that publishes events (issues 3, 4 and 6 build it).
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

pub mod events;
pub mod geometry;
pub mod motion;
pub mod scenario;

pub use events::{SensorModel, SimEvent, TimedEvent};
pub use scenario::{GeneratedTrace, Length, Model, RedChoice, Scenario, ScenarioError};
