//! Thresholding (Section 5.3.2): keep the sets with the largest l1
//! contribution |c_α|·W(|α|) — which is exactly |m_α|, the stored mass — and
//! drop the rest. Our atoms keep every mass positive (see
//! [`atom`](super::atom)), so dropping removes hypotheses and never makes the
//! belief negative. Fully local: a leader can threshold its own atoms without
//! asking anyone (Section 5.4.3).

use super::atom::Atom;
use super::RadonBelief;
use crate::error::BeliefError;
use rustc_hash::{FxHashMap, FxHashSet};

/// Relative difference below which two masses tie.
const TIE: f64 = 1e-9;

/// Keeps the `keep` heaviest atoms of `masses`; returns the removed ones (in
/// no particular order). Selects on a copy of the weights and removes in
/// place, so kept atoms are not rehashed.
pub(super) fn split_off_lightest(
    masses: &mut FxHashMap<Atom, f64>,
    keep: usize,
) -> Vec<(Atom, f64)> {
    if masses.len() <= keep {
        return Vec::new();
    }
    let mut sizes: Vec<f64> = masses.values().map(|m| m.abs()).collect();
    let cut = if keep == 0 {
        f64::INFINITY
    } else {
        *sizes
            .select_nth_unstable_by(keep - 1, |x, y| y.total_cmp(x))
            .1
    };
    // Atoms clearly heavier than the cut all stay; ties at the cut fill the
    // remaining places, smallest atoms first. Masses equal but for rounding
    // count as ties (sets equal by symmetry are computed along different
    // paths), so the choice depends neither on the map's order nor on the
    // last bits: a leader's share and the whole belief drop the same sets.
    let band = cut * TIE;
    let places = keep - sizes[..keep].iter().filter(|&&x| x > cut + band).count();
    let mut tied: Vec<Atom> = masses
        .iter()
        .filter(|(_, m)| (m.abs() - cut).abs() <= band)
        .map(|(a, _)| a.clone())
        .collect();
    tied.sort_unstable();
    tied.truncate(places);
    let kept_ties: FxHashSet<Atom> = tied.into_iter().collect();
    let mut removed = Vec::with_capacity(masses.len() - keep);
    for (atom, m) in masses.extract_if(|atom, m| {
        let size = m.abs();
        size <= cut + band && !kept_ties.contains(atom)
    }) {
        removed.push((atom, m));
    }
    removed
}

impl RadonBelief {
    /// The removed atoms are returned so that OMP can re-express part of them.
    pub(super) fn split_off_lightest(&mut self, keep: usize) -> Vec<(Atom, f64)> {
        split_off_lightest(&mut self.masses, keep)
    }

    /// Thresholds down to `budget` atoms and renormalizes.
    pub(crate) fn threshold(&mut self, budget: usize) -> Result<(), BeliefError> {
        let removed = self.split_off_lightest(budget.max(1));
        if let Err(e) = self.renormalize() {
            // Only a signed expansion can get here; put everything back.
            self.masses.extend(removed);
            return Err(e);
        }
        self.stats.thresholdings += 1;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use crate::event::{Field, Observe};
    use crate::filter::PropertyFilter;
    use crate::radon::RadonBelief;

    #[test]
    fn keeps_heaviest_and_stays_normalized() {
        let mut belief = RadonBelief::new(Field::uniform(8, 4)).unwrap();
        for t in 0..5 {
            belief
                .observe(Observe {
                    track: t,
                    red: 0.8,
                    blue: 0.2,
                })
                .unwrap();
        }
        let n = belief.coefficients();
        assert!(n > 10);
        let mut heaviest: Vec<f64> = belief.masses().map(|(_, m)| m.abs()).collect();
        heaviest.sort_by(|a, b| b.total_cmp(a));
        belief.threshold(10).unwrap();
        assert_eq!(belief.coefficients(), 10);
        let mut kept: Vec<f64> = belief.masses().map(|(_, m)| m.abs()).collect();
        kept.sort_by(|a, b| b.total_cmp(a));
        // The kept sets are the 10 heaviest: their relative sizes are unchanged.
        for (mass, heavy) in kept.iter().zip(&heaviest) {
            assert!((mass / kept[0] - heavy / heaviest[0]).abs() < 1e-12);
        }
        let p = belief.marginals().unwrap();
        assert!((p.iter().sum::<f64>() - 4.0).abs() < 1e-9);
    }
}
