//! Thresholding (Section 5.3.2): keep the sets with the largest l1
//! contribution |c_α|·W(|α|) — which is exactly |m_α|, the stored mass — and
//! drop the rest. Fully local: a leader can threshold its own sets without
//! asking anyone (Section 5.4.3).

use super::RadonBelief;
use crate::error::BeliefError;
use crate::track_set::TrackSet;

impl RadonBelief {
    /// Keeps the `keep` heaviest sets; returns the dropped ones, heaviest
    /// first, so that OMP can re-express part of them.
    pub(super) fn split_off_lightest(&mut self, keep: usize) -> Vec<(TrackSet, f64)> {
        if self.masses.len() <= keep {
            return Vec::new();
        }
        let mut all: Vec<(TrackSet, f64)> = self.masses.drain().collect();
        // Heaviest first; ties broken by the set so that runs are deterministic.
        let by_weight = |x: &(TrackSet, f64), y: &(TrackSet, f64)| {
            y.1.abs().total_cmp(&x.1.abs()).then_with(|| x.0.cmp(&y.0))
        };
        if keep > 0 {
            all.select_nth_unstable_by(keep - 1, by_weight);
        }
        let mut dropped = all.split_off(keep);
        dropped.sort_unstable_by(by_weight);
        self.masses.extend(all);
        dropped
    }

    /// Thresholds down to `keep` sets and renormalizes.
    pub fn threshold(&mut self, keep: usize) -> Result<(), BeliefError> {
        let before = self.clone();
        self.split_off_lightest(keep.max(1));
        self.stats.thresholdings += 1;
        self.renormalize().inspect_err(|_| *self = before)
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
