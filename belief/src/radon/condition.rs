//! Conditioning on an observation: Algorithm 2 of the paper (Section 5.2)
//! specialised to the likelihoods of the trace format, L = b·φ_∅ + (a − b)·φ_t
//! (a = `red`, b = `blue`).
//!
//! φ_α·φ_∅ = φ_α and φ_α·φ_t = φ_{α ∪ {t}} (or 0 when |α ∪ {t}| exceeds every
//! admissible red count), so with ρ = a/b and the factor b kept in the scale
//! (the paper's "b = 1" trick, which Section 5.4 relies on):
//! - α ∋ t: c_α ← ρ·c_α;
//! - α ∌ t: c_α unchanged, and (ρ − 1)·c_α is added to α ∪ {t}.
//!
//! When b = 0 we factor out a instead: sets without t vanish and pass all of
//! their weight to α ∪ {t}. The result is exact when nothing is pruned.
//! In masses (m = c·W(|α|)) the addition to α ∪ {t} is (ρ − 1)·m_α·W(|α|+1)/W(|α|).

use super::RadonBelief;
use crate::error::BeliefError;
use crate::event::Observe;
use crate::track_set::TrackSet;
use rustc_hash::FxHashMap;
use std::collections::hash_map::Entry;

impl RadonBelief {
    pub(super) fn condition(&mut self, observe: Observe) -> Result<(), BeliefError> {
        let t = observe.track;
        // Factor the likelihood as scale·(φ_∅·base + φ_t·(ρ − base)).
        let (scale, base, rho) = if observe.blue > 0.0 {
            (observe.blue, 1.0, observe.red / observe.blue)
        } else {
            (observe.red, 0.0, 1.0)
        };
        let partners: Option<Vec<u32>> = self
            .options
            .distributed_rule
            .then(|| self.mixing_log.partners(t).to_vec());
        let grows = |set: &TrackSet| match &partners {
            Some(p) => set.meets(p),
            None => true,
        };

        // First a read-only pass for the new total, so that an impossible
        // observation leaves the belief untouched.
        let mut total = 0.0;
        for (set, &m) in &self.masses {
            if set.contains(t) {
                total += rho * m;
            } else {
                total += base * m;
                if grows(set) {
                    total += (rho - base) * m * self.weights.ratio(set.len());
                }
            }
        }
        let old_total = self.total_mass();
        if !(total.is_finite() && total > 0.0) {
            return Err(BeliefError::ImpossibleObservation {
                probability: scale * total / old_total,
            });
        }

        let mut added: FxHashMap<TrackSet, f64> = FxHashMap::default();
        self.masses.retain(|set, m| {
            if set.contains(t) {
                *m *= rho;
            } else {
                let ratio = self.weights.ratio(set.len());
                if ratio > 0.0 && grows(set) && rho != base {
                    *added.entry(set.with(t)).or_insert(0.0) += (rho - base) * *m * ratio;
                }
                *m *= base;
            }
            *m != 0.0
        });
        for (set, m) in added {
            match self.masses.entry(set) {
                Entry::Occupied(mut held) => {
                    *held.get_mut() += m;
                    if *held.get() == 0.0 {
                        held.remove();
                    }
                }
                Entry::Vacant(free) => {
                    if m != 0.0 {
                        free.insert(m);
                    }
                }
            }
        }
        self.log_scale += scale.ln();
        self.renormalize()
    }
}
