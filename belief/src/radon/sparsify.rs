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

use super::omp::OmpOptions;
use super::RadonBelief;
use crate::error::BeliefError;

/// A coefficient budget and the approximation that enforces it.
#[derive(Debug, Clone, PartialEq)]
pub struct Sparsify {
    /// The most sets the belief may hold after an event.
    pub budget: usize,
    pub method: SparsifyMethod,
}

#[derive(Debug, Clone, PartialEq)]
pub enum SparsifyMethod {
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
pub struct OmpSchedule {
    mixes: u32,
    observations: u32,
}

impl OmpSchedule {
    pub fn mixed(&mut self) {
        self.mixes += 1;
    }

    pub fn observed(&mut self) {
        self.observations += 1;
    }

    /// At least `every` events since the last run, at least half of them
    /// mixes.
    pub fn due(&self, omp: &OmpOptions) -> bool {
        self.mixes + self.observations >= omp.every && self.mixes >= self.observations
    }

    pub fn ran(&mut self) {
        *self = OmpSchedule::default();
    }
}

impl RadonBelief {
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
