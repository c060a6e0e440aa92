//! When and how the belief is made sparse again (Section 5.3, and the
//! "Timing for Sparsification" discussion of Section 5.5).
//!
//! Rollup and conditioning can each double the number of sets (Theorems 3,
//! 4). Once the count exceeds the budget:
//! - `Threshold` drops the lightest sets (Section 5.3.2);
//! - `Overcomplete` first lets OMP re-express the heaviest of the sets that
//!   thresholding would drop on lower-order sets (Section 5.3.1) — mixing
//!   smooths the belief, and a family {S ∪ {x}} spread by mixing is nearly
//!   one φ_S — then thresholds what is left. OMP runs only after a run of
//!   mixing (at least `every` events since its last run, at least half of
//!   them mixes); after observations the belief is peaky and thresholding
//!   suits it (Section 5.5).
//!
//! ## An observation the approximation has ruled out
//! Dropping sets (and the distributed rule, which grows only some) can
//! leave the belief without the sets a later certain sighting allows,
//! although the world could have produced it: the dropped sets held the
//! truth. Such a belief cannot tell a valid sighting from an impossible
//! one, so it answers on by one rule, not Bayes' rule: when a sighting has
//! no mass left, a share [`RESTORE_SHARE`] of the belief is moved to the
//! uniform one (φ_∅, every admissible set as likely as under the prior,
//! which the distributed rule grows on every sighting), and the sighting is
//! conditioned on as usual. Counted in
//! [`RadonStats::restorations`](super::RadonStats::restorations). The exact
//! belief (no budget, exact conditioning) drops nothing: a sighting it
//! rules out contradicts the stream itself, and it follows the repair rule
//! of every filter (`crate::repair`), the same move with the smaller share
//! `REPAIR_SHARE`, counted alike. A sighting the prior rules out too (e.g.
//! a certain red one with k = 0) is set aside.

use super::atom::Atom;
use super::omp::OmpOptions;
use super::RadonBelief;
use crate::error::BeliefError;
use rustc_hash::FxHashMap;

/// The share of the belief moved to the uniform one when an approximation
/// has ruled out a sighting (see the module documentation): small, so that
/// the belief keeps what it knew about everything else.
pub(crate) const RESTORE_SHARE: f64 = 1e-6;

/// Moves `share` of the masses to the uniform belief φ_∅.
pub(super) fn restore_uniform(masses: &mut FxHashMap<Atom, f64>, share: f64) {
    let total: f64 = masses.values().sum();
    let moved = share * total;
    masses.values_mut().for_each(|m| *m *= 1.0 - share);
    // φ_∅ even under the distributed rule, which grows it on every
    // sighting (its 1-sets grow only when they meet the mixing log, and a
    // certain sighting of a track that has not mixed would find nothing).
    *masses.entry(Atom::default()).or_insert(0.0) += moved;
}

/// A coefficient budget and the approximation that enforces it.
#[derive(Debug, Clone, PartialEq)]
pub struct Sparsify {
    /// The most sets the belief may hold after an event.
    pub budget: usize,
    pub(crate) method: SparsifyMethod,
}

#[derive(Debug, Clone, PartialEq)]
pub(crate) enum SparsifyMethod {
    Threshold,
    Overcomplete(OmpOptions),
}

impl Sparsify {
    pub fn threshold(budget: usize) -> Self {
        Sparsify {
            budget,
            method: SparsifyMethod::Threshold,
        }
    }

    pub fn overcomplete(budget: usize) -> Self {
        Sparsify {
            budget,
            method: SparsifyMethod::Overcomplete(OmpOptions::for_budget(budget)),
        }
    }

    pub fn validate(&self) -> Result<(), BeliefError> {
        if self.budget == 0 {
            return Err(BeliefError::Unsupported {
                method: "sparsify",
                what: "a budget of 0 coefficients",
            });
        }
        if let SparsifyMethod::Overcomplete(omp) = &self.method {
            omp.validate(self.budget)?;
        }
        Ok(())
    }
}

/// Mixes and observations since OMP last ran, to time it after runs of
/// mixing (Section 5.5, "Timing for Sparsification"). The whole belief and
/// each leader's share keep one.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub(crate) struct OmpSchedule {
    mixes: u32,
    observations: u32,
}

impl OmpSchedule {
    pub(crate) fn mixed(&mut self) {
        self.mixes += 1;
    }

    pub(crate) fn observed(&mut self) {
        self.observations += 1;
    }

    /// At least `every` events since the last run, at least half of them
    /// mixes.
    pub(crate) fn due(&self, omp: &OmpOptions) -> bool {
        self.mixes + self.observations >= omp.every && self.mixes >= self.observations
    }

    pub(crate) fn ran(&mut self) {
        *self = OmpSchedule::default();
    }
}

impl RadonBelief {
    /// Whether the belief may have dropped sets the events allow: a budget
    /// or the distributed rule.
    pub(super) fn approximate(&self) -> bool {
        self.options.sparsify.is_some() || self.options.distributed_rule
    }

    pub(super) fn sparsify_now(&mut self, sparsify: &Sparsify) -> Result<(), BeliefError> {
        match &sparsify.method {
            SparsifyMethod::Threshold => {
                self.threshold(sparsify.budget)?;
            }
            SparsifyMethod::Overcomplete(omp) => {
                if self.since_omp.due(omp) {
                    self.pursue(sparsify.budget, omp)?;
                    self.since_omp.ran();
                }
                if self.masses.len() > sparsify.budget {
                    self.threshold(sparsify.budget)?;
                }
            }
        }
        Ok(())
    }
}
