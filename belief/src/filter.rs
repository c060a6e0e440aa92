//! The one interface every property filter offers — the Radon engine, its
//! sparse approximations, the exact dense filter, the low-order baselines and
//! the particle filter — so replay, evaluation and tests treat them alike.

use crate::error::BeliefError;
use crate::event::{Event, Field, Mix, Observe};

/// A belief over which tracks carry red targets, updated event by event.
///
/// Every update is all-or-nothing: when it returns an error the filter is
/// exactly as it was before the call.
pub trait PropertyFilter {
    /// The field the filter was built for.
    fn field(&self) -> &Field;

    /// Rollup for a mixing event.
    fn mix(&mut self, mix: Mix) -> Result<(), BeliefError>;

    /// Conditioning on an observation.
    fn observe(&mut self, observe: Observe) -> Result<(), BeliefError>;

    /// P(track t is red) for every track, under the (normalized) belief.
    fn marginals(&self) -> Result<Vec<f64>, BeliefError>;

    /// How many numbers the filter stores now (coefficients, states,
    /// particles): the memory figure of the paper's tables.
    fn coefficients(&self) -> usize;

    /// How many sightings the filter took by the repair rule or set aside
    /// (the `repair` module): 0 on every stream that never contradicts
    /// itself.
    fn repairs(&self) -> u64 {
        0
    }

    /// Applies one event (checked against the field first).
    fn apply(&mut self, event: &Event) -> Result<(), BeliefError> {
        self.field().check(event)?;
        match *event {
            Event::Mix(mix) => self.mix(mix),
            Event::Observe(observe) => self.observe(observe),
        }
    }

    /// The tracks predicted red: the k with the largest marginals when k is
    /// known (the spec's scoring rule), otherwise every track whose marginal
    /// is at least ½ (which minimizes the expected number of mislabeled
    /// tracks). Sorted ascending.
    fn predicted_red(&self) -> Result<Vec<u32>, BeliefError> {
        let marginals = self.marginals()?;
        Ok(predict_red(&marginals, self.field().red.known()))
    }
}

/// The prediction rule of [`PropertyFilter::predicted_red`], for marginals
/// computed elsewhere. Ties are broken towards the lower track id so that
/// replays are deterministic.
pub fn predict_red(marginals: &[f64], k: Option<usize>) -> Vec<u32> {
    let mut red: Vec<u32> = match k {
        Some(k) => {
            let mut order: Vec<u32> = (0..marginals.len() as u32).collect();
            // The order is total (ties go to the lower track), so the k
            // first of a selection are those of a sort, in linear time: a
            // coordinator answers this for every track at every query.
            let by_rank = |&x: &u32, &y: &u32| {
                marginals[y as usize]
                    .total_cmp(&marginals[x as usize])
                    .then(x.cmp(&y))
            };
            if k < order.len() {
                order.select_nth_unstable_by(k, by_rank);
                order.truncate(k);
            }
            order
        }
        None => (0..marginals.len() as u32)
            .filter(|&t| marginals[t as usize] >= 0.5)
            .collect(),
    };
    red.sort_unstable();
    red
}

/// The spec's tracking error at one truth line: the fraction of tracks whose
/// predicted label differs from the truth.
pub fn tracking_error(tracks: usize, predicted: &[u32], truth: &[u32]) -> f64 {
    let mut label = vec![0u8; tracks];
    for &t in predicted {
        label[t as usize] ^= 1;
    }
    for &t in truth {
        label[t as usize] ^= 2;
    }
    let wrong = label.iter().filter(|&&l| l == 1 || l == 2).count();
    wrong as f64 / tracks as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prediction_takes_k_largest_and_breaks_ties_low() {
        assert_eq!(predict_red(&[0.5, 0.9, 0.5, 0.1], Some(2)), vec![0, 1]);
        assert_eq!(predict_red(&[0.5, 0.9, 0.4, 0.1], None), vec![0, 1]);
    }

    proptest::proptest! {
        /// The selection gives the k first of the spec's order (largest
        /// marginal first, ties to the lower track), as a full sort does;
        /// marginals drawn from a few values make ties the rule.
        #[test]
        fn prediction_is_the_k_first_of_a_full_sort(
            levels in proptest::collection::vec(0u8..4, 0..60),
            k in 0usize..70,
        ) {
            let marginals: Vec<f64> = levels.iter().map(|&l| f64::from(l) / 3.0).collect();
            let mut sorted: Vec<u32> = (0..marginals.len() as u32).collect();
            sorted.sort_by(|&x, &y| {
                marginals[y as usize].total_cmp(&marginals[x as usize]).then(x.cmp(&y))
            });
            sorted.truncate(k);
            sorted.sort_unstable();
            proptest::prop_assert_eq!(predict_red(&marginals, Some(k)), sorted);
        }
    }

    #[test]
    fn error_counts_mislabeled_tracks() {
        assert_eq!(tracking_error(4, &[0, 1], &[0, 1]), 0.0);
        assert_eq!(tracking_error(4, &[0, 1], &[2, 3]), 1.0);
        assert_eq!(tracking_error(4, &[0, 1], &[1, 2]), 0.5);
    }
}
