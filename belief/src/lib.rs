//! # idmesh-belief — the inference engine
//!
//! Pure, synchronous, no I/O: every filter here takes events and answers
//! questions, so it can be tested and benchmarked alone and embedded in the
//! leader actors unchanged.
//!
//! A map of the crate (its modules are private: what other crates use is
//! re-exported below, by concern; `workload` stays a public namespace):
//! - `event` — the `mix` and `observe` events and the [`Field`] a filter
//!   starts from (n tracks, k red or a prior over k, initial assignment).
//! - `from_trace` — the field a trace header or a stream's `Begin`
//!   describes and the event a trace line carries: where the protocol's
//!   types become the engine's.
//! - `filter` — [`PropertyFilter`], the interface every property filter
//!   offers, and the spec's prediction and scoring rules.
//! - `track_set` — [`TrackSet`], the index α of a Radon basis function.
//! - `weights` — binomial weights W(j) = C(n − j, k − j) in log space.
//! - `radon` — the core: a sparse belief on the overcomplete Radon
//!   dictionary (Jiang et al., TOSN 2013, Sections 4–5): rollup (Alg. 1),
//!   conditioning (Alg. 2), exact answers, thresholding and OMP (Sec. 5.3),
//!   and the distributed conditioning rule (Sec. 5.4).
//! - `factored` — a product of small exact beliefs over groups of tracks
//!   coupled through the red count, split by moment matching when a group
//!   grows too large.
//! - `baseline` — yardsticks: the exact dense filter over all k-sets and
//!   the low-order Radon filters of order 1, 2, 3 (Table III).
//! - `particle` — [`ParticleFilter`], sequential Monte Carlo over red
//!   sets: the yardstick a practitioner would reach for.
//! - `repair` — the rule every filter follows when a sighting contradicts
//!   its belief: taken after a small repair, or set aside.
//! - `support` — the support floor: a mass the events allow never rounds
//!   to 0 (the Radon engine's and the factored tables').
//! - [`workload`] — seeded random event streams for tests and benchmarks.
//!
//! Identity beliefs (who is on which track; Shin et al., IPSN 2005) are
//! the crate beside this one, `idmesh-identity`, which builds on the
//! events, errors, scores and Radon belief here.

mod baseline;
mod error;
mod event;
mod factored;
mod filter;
mod from_trace;
mod particle;
mod radon;
mod repair;
mod scoring;
mod support;
mod track_set;
mod weights;
pub mod workload;

// Events, the field a filter starts from, and what goes wrong.
pub use error::BeliefError;
pub use event::{Event, Field, Mix, Observe, RedCount};
pub use track_set::TrackSet;
// Where the protocol's trace lines and headers become the engine's.
pub use from_trace::{event_of, field_of, mix_of};
// The interface of every property filter, and the spec's scores.
pub use filter::{predict_red, tracking_error, PropertyFilter};
pub use scoring::{
    brier_score, expected_tracking_error, log_loss, mean_with_interval, Reliability, LOG_LOSS_FLOOR,
};
// The Radon belief, and what leaders exchange of it.
pub use radon::{
    Atom, Growth, MixingLog, PartialSums, RadonBelief, RadonOptions, RadonShare, RadonStats,
    Sparsify,
};
// The factored belief, and what leaders exchange of it.
pub use factored::{
    coupled_marginals, CountPart, Coupling, CouplingTree, FactoredBelief, FactoredOptions,
    FactoredShare, FactoredStats, HeldComponent, SplitRule,
};
// Yardsticks: the exact dense filter, low-order Radon filters, particles.
pub use baseline::{DenseFilter, LowOrderFilter, LowOrderRepair, MAX_STATES};
pub use particle::ParticleFilter;
