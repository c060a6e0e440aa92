//! The exact identity filter: the full distribution over all N! assignments
//! of identities to tracks (Shin et al., IPSN 2005, Section 2, "Optimal
//! identity management"), for N ≤ 9. It is the yardstick every approximate
//! identity filter is tested against.
//!
//! - Mixing (Definition 2, eq. 1) is the convolution with the two-point
//!   distribution m = (1 − swap)·δ(identity) + swap·δ(transposition (a b)):
//!   q(π) = (1 − swap)·p(π) + swap·p(π ∘ (a b)). With assignments indexed by
//!   Lehmer rank ([`Permutations`]) this pairs every rank with the rank of
//!   its transposed assignment: O(N!·N), not the paper's O((N!)²).
//! - Evidence (Definition 3, Bayes' rule) multiplies p(π) by
//!   P(read | π(track)) of the [`Identify`] read model and renormalizes.

use super::event::{check_assignment, check_identify, check_mix, Identify};
use super::filter::{IdentityFilter, Marginals};
use super::permutation::Permutations;
use idmesh_belief::BeliefError;
use idmesh_belief::Mix;
use std::sync::Arc;

/// The exact distribution over the N! assignments.
#[derive(Debug, Clone)]
pub struct ExactPermutationFilter {
    /// Shared: clones of a filter (e.g. to try an update) reuse the table.
    perms: Arc<Permutations>,
    /// probs[rank] = P(assignment of that rank); sums to 1.
    probs: Vec<f64>,
}

impl ExactPermutationFilter {
    /// Every assignment equally likely.
    pub fn uniform(n: usize) -> Result<Self, BeliefError> {
        let perms = Permutations::new(n)?;
        let count = perms.count();
        Ok(ExactPermutationFilter {
            perms: Arc::new(perms),
            probs: vec![1.0 / count as f64; count],
        })
    }

    /// Track t surely carries identity `assignment[t]`.
    pub fn from_assignment(assignment: &[u32]) -> Result<Self, BeliefError> {
        let n = assignment.len();
        if n == 0 {
            return Err(BeliefError::NoTracks);
        }
        check_assignment(n, assignment)?;
        let perms = Permutations::new(n)?;
        let start: Vec<u8> = assignment.iter().map(|&i| i as u8).collect();
        let mut probs = vec![0.0; perms.count()];
        probs[perms.rank(&start)] = 1.0;
        Ok(ExactPermutationFilter {
            perms: Arc::new(perms),
            probs,
        })
    }

    /// p(π) ∝ exp(Σ_t l\[t\]\[π(t)\]): the distribution an information matrix
    /// L encodes (Shin et al., Section 3.1). Entries may be −∞ (impossible
    /// pairings) but not +∞ or NaN, and some assignment must stay possible.
    #[cfg(test)]
    pub(crate) fn from_log_likelihoods(l: &[Vec<f64>]) -> Result<Self, BeliefError> {
        let n = super::event::check_square(l)?;
        if let Some(&bad) = l
            .iter()
            .flatten()
            .find(|x| x.is_nan() || **x == f64::INFINITY)
        {
            return Err(BeliefError::Numerical {
                step: "log-likelihood matrix",
                detail: format!("entry {bad} is not finite or −∞"),
            });
        }
        let perms = Permutations::new(n)?;
        let log_p: Vec<f64> = (0..perms.count())
            .map(|r| {
                perms
                    .get(r)
                    .iter()
                    .enumerate()
                    .map(|(t, &i)| l[t][i as usize])
                    .sum()
            })
            .collect();
        let top = log_p.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        if top == f64::NEG_INFINITY {
            return Err(BeliefError::Degenerate { normalizer: 0.0 });
        }
        let mut probs: Vec<f64> = log_p.iter().map(|&x| (x - top).exp()).collect();
        normalize(&mut probs)?;
        Ok(ExactPermutationFilter {
            perms: Arc::new(perms),
            probs,
        })
    }

    /// P(assignment) for every assignment, indexed by Lehmer rank.
    #[cfg(test)]
    pub(crate) fn probabilities(&self) -> &[f64] {
        &self.probs
    }

    /// P(track t carries `assignment[t]` for every t).
    #[cfg(test)]
    pub(crate) fn probability(&self, assignment: &[u32]) -> Result<f64, BeliefError> {
        check_assignment(self.size(), assignment)?;
        let perm: Vec<u8> = assignment.iter().map(|&i| i as u8).collect();
        Ok(self.probs[self.perms.rank(&perm)])
    }

    /// The single most probable joint assignment (lowest rank on ties).
    #[cfg(test)]
    pub(crate) fn most_probable(&self) -> Vec<u32> {
        let best = self
            .probs
            .iter()
            .enumerate()
            .fold((0, f64::NEG_INFINITY), |(br, bp), (r, &p)| {
                if p > bp {
                    (r, p)
                } else {
                    (br, bp)
                }
            })
            .0;
        self.perms.get(best).iter().map(|&i| i as u32).collect()
    }

    /// The entropy of the joint distribution, in nats.
    #[cfg(test)]
    pub(crate) fn entropy(&self) -> f64 {
        -self
            .probs
            .iter()
            .filter(|&&p| p > 0.0)
            .map(|&p| p * p.ln())
            .sum::<f64>()
    }
}

/// Divides by the sum; refuses a sum that is 0 or not finite.
#[cfg(test)]
fn normalize(probs: &mut [f64]) -> Result<(), BeliefError> {
    let total: f64 = probs.iter().sum();
    if !(total.is_finite() && total > 0.0) {
        return Err(BeliefError::Degenerate { normalizer: total });
    }
    for p in probs.iter_mut() {
        *p /= total;
    }
    Ok(())
}

impl IdentityFilter for ExactPermutationFilter {
    fn size(&self) -> usize {
        self.perms.size()
    }

    fn mix(&mut self, mix: Mix) -> Result<(), BeliefError> {
        check_mix(self.size(), &mix)?;
        let (a, b, s) = (mix.a as usize, mix.b as usize, mix.swap);
        // Nothing below can fail, so updating in place is all-or-nothing.
        for r in 0..self.perms.count() {
            let partner = self.perms.rank_swapped(r, a, b);
            if r < partner {
                let (p, q) = (self.probs[r], self.probs[partner]);
                self.probs[r] = (1.0 - s) * p + s * q;
                self.probs[partner] = (1.0 - s) * q + s * p;
            }
        }
        Ok(())
    }

    fn identify(&mut self, identify: Identify) -> Result<(), BeliefError> {
        let n = self.size();
        check_identify(n, &identify)?;
        let (t, read) = (identify.track as usize, identify.identity as u8);
        let (right, wrong) = (identify.accuracy, identify.wrong_read_likelihood(n));
        self.perms
            .condition_on_read(&mut self.probs, t, read, right, wrong)
    }

    fn marginals(&self) -> Result<Marginals, BeliefError> {
        let n = self.size();
        let mut m = vec![vec![0.0; n]; n];
        for (r, &p) in self.probs.iter().enumerate() {
            if p != 0.0 {
                for (t, &i) in self.perms.get(r).iter().enumerate() {
                    m[t][i as usize] += p;
                }
            }
        }
        Ok(m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::doubly_stochastic_residual;
    use crate::workload::{generate, IdentityWorkloadSpec};
    use proptest::prelude::*;

    fn read(track: u32, identity: u32, accuracy: f64) -> Identify {
        Identify {
            track,
            identity,
            accuracy,
        }
    }

    #[test]
    fn slides_example_mix_of_a_known_assignment() {
        // The slides' example: start at the identity, mix tracks 0 and 1
        // with α = ½ → half on I, half on I(1,2).
        let mut f = ExactPermutationFilter::from_assignment(&[0, 1, 2]).unwrap();
        f.mix(Mix {
            a: 0,
            b: 1,
            swap: 0.5,
        })
        .unwrap();
        assert_eq!(f.probability(&[0, 1, 2]).unwrap(), 0.5);
        assert_eq!(f.probability(&[1, 0, 2]).unwrap(), 0.5);
        let m = f.marginals().unwrap();
        assert_eq!(m[2], vec![0.0, 0.0, 1.0]);
        assert_eq!(m[0], vec![0.5, 0.5, 0.0]);
        // A read of identity 0 on track 0 with the paper's accuracy.
        f.identify(read(0, 0, 0.9)).unwrap();
        let p = f.probability(&[0, 1, 2]).unwrap();
        assert!((p - 0.9 / (0.9 + 0.05)).abs() < 1e-15);
    }

    #[test]
    fn perfect_reads_pin_the_assignment() {
        let mut f = ExactPermutationFilter::uniform(4).unwrap();
        for (t, i) in [(0, 2), (1, 0), (2, 3)] {
            f.identify(read(t, i, 1.0)).unwrap();
        }
        assert_eq!(f.most_probable(), vec![2, 0, 3, 1]);
        assert!((f.probability(&[2, 0, 3, 1]).unwrap() - 1.0).abs() < 1e-12);
        assert!(f.entropy().abs() < 1e-12);
        // A contradicting perfect read is impossible and changes nothing.
        let before = f.probabilities().to_vec();
        assert!(matches!(
            f.identify(read(3, 2, 1.0)),
            Err(BeliefError::ImpossibleObservation { .. })
        ));
        assert_eq!(f.probabilities(), &before[..]);
    }

    #[test]
    fn mixing_only_raises_entropy() {
        // Lemma 1 of the paper.
        let mut f = ExactPermutationFilter::from_assignment(&[0, 1, 2, 3, 4]).unwrap();
        let mut h = f.entropy();
        for (a, b) in [(0, 1), (1, 2), (3, 4), (0, 4), (2, 3)] {
            f.mix(Mix { a, b, swap: 0.3 }).unwrap();
            assert!(f.entropy() >= h - 1e-12);
            h = f.entropy();
        }
    }

    #[test]
    fn refuses_bad_input_and_size() {
        assert!(matches!(
            ExactPermutationFilter::uniform(10),
            Err(BeliefError::TooLarge { .. })
        ));
        assert!(ExactPermutationFilter::from_assignment(&[0, 0]).is_err());
        let mut f = ExactPermutationFilter::uniform(3).unwrap();
        let before = f.probabilities().to_vec();
        assert!(f
            .mix(Mix {
                a: 0,
                b: 3,
                swap: 0.5
            })
            .is_err());
        assert!(f.identify(read(0, 3, 0.9)).is_err());
        assert!(f.identify(read(0, 1, 0.0)).is_err());
        assert_eq!(f.probabilities(), &before[..]);
        assert!(ExactPermutationFilter::from_log_likelihoods(&[
            vec![f64::NEG_INFINITY, f64::NEG_INFINITY],
            vec![0.0, 0.0]
        ])
        .is_err());
    }

    #[test]
    fn log_likelihood_start_is_the_exponential_family() {
        let l = vec![vec![1.0, 0.0], vec![0.0, 0.5]];
        let f = ExactPermutationFilter::from_log_likelihoods(&l).unwrap();
        let id = (1.5f64).exp();
        let sw = 1.0;
        assert!((f.probability(&[0, 1]).unwrap() - id / (id + sw)).abs() < 1e-15);
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        /// The marginals of any exact belief are doubly stochastic: each
        /// track carries one identity and each identity is on one track.
        #[test]
        fn marginals_are_doubly_stochastic(
            n in 1usize..=6,
            seed in any::<u64>(),
            mix_share in 0.0f64..=1.0,
            accuracy in 0.2f64..=0.99,
            known in any::<bool>(),
        ) {
            let spec = IdentityWorkloadSpec {
                tracks: n,
                events: 30,
                mix_share,
                swap: 0.4,
                accuracy,
                neighbourhood: n,
                seed,
            };
            let w = generate(&spec).unwrap();
            let mut f = if known {
                ExactPermutationFilter::from_assignment(&w.initial).unwrap()
            } else {
                ExactPermutationFilter::uniform(n).unwrap()
            };
            for e in &w.events {
                f.apply(e).unwrap();
                let m = f.marginals().unwrap();
                prop_assert!(doubly_stochastic_residual(&m) < 1e-9);
                prop_assert!(m.iter().flatten().all(|&x| x >= 0.0));
            }
        }
    }
}
