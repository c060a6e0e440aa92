//! Answers from the coefficients, exact for the represented belief.
//!
//! The paper scores tracks through the pseudoinverse projection onto the
//! first-order Radon basis (Section 5.5, "Prediction"). We give the exact
//! posterior marginals instead: the k-sets holding t that φ_α covers are
//! W(|α|) of them if t ∈ α and W(|α| + 1) otherwise, so
//!
//! P(t red) = [Σ_{α ∋ t} m_α + Σ_{α ∌ t} m_α·W(|α|+1)/W(|α|)] / Σ_α m_α,
//!
//! one pass over the sets. Likewise P(S all red) = Σ_α m_α·W(|α ∪ S|)/W(|α|)
//! / Σ m_α, and the normalizing constant Z = Σ_x f(x) = e^{log_scale}·Σ m_α.

use super::share::PartialSums;
use super::RadonBelief;
use crate::error::BeliefError;
use crate::event::RedCount;
use crate::track_set::TrackSet;
use crate::weights::ln_binomial;

impl RadonBelief {
    fn checked_total(&self) -> Result<f64, BeliefError> {
        let total = self.total_mass();
        if total.is_finite() && total > 0.0 {
            Ok(total)
        } else {
            Err(BeliefError::Degenerate { normalizer: total })
        }
    }

    /// P(track t is red) for every track.
    pub(crate) fn exact_marginals(&self) -> Result<Vec<f64>, BeliefError> {
        self.checked_total()?;
        PartialSums::of(&self.masses, &self.weights, self.log_scale).marginals(self.field.tracks)
    }

    /// P(every track of `set` is red).
    pub fn prob_all_red(&self, set: &TrackSet) -> Result<f64, BeliefError> {
        for &t in set.tracks() {
            self.field.check_track(t)?;
        }
        let total = self.checked_total()?;
        let sum: f64 = self
            .masses
            .iter()
            .filter(|(atom, _)| atom.blue.intersection_len(set) == 0)
            .map(|(atom, &m)| {
                let (i, o) = atom.sizes();
                m * self
                    .weights
                    .ratio_between((i, o), (atom.red.union_len(set), o))
            })
            .sum();
        Ok(sum / total)
    }

    /// ln Z, Z = Σ_x f(x): the unnormalized belief's total, i.e. the prior
    /// mass times the likelihood of every observation so far.
    pub fn log_normalizer(&self) -> f64 {
        self.log_scale + self.total_mass().ln()
    }

    /// P(exactly j tracks are red) for j = 0..=n, when the count is unknown;
    /// a single 1 at k when it is known.
    pub fn count_posterior(&self) -> Result<Vec<f64>, BeliefError> {
        let n = self.field.tracks;
        let total = self.checked_total()?;
        let mut posterior = vec![0.0; n + 1];
        match &self.field.red {
            RedCount::Known(k) => posterior[*k] = 1.0,
            RedCount::Unknown { prior } => {
                let prior_total: f64 = prior.iter().sum();
                // φ_{α|β} covers C(n−|α|−|β|, j−|α|) sets of size j, each with
                // weight p(j)/C(n, j); divide by W(|α|, |β|) to turn mass
                // back into a coefficient.
                for (atom, &m) in &self.masses {
                    let (i, o) = atom.sizes();
                    let ln_w = self.weights.ln2(i, o);
                    for (j, p) in prior.iter().enumerate().skip(i) {
                        if *p > 0.0 && j - i <= n - i - o {
                            let ln_cover = ln_binomial(n - i - o, j - i) - ln_binomial(n, j)
                                + (p / prior_total).ln();
                            posterior[j] += m * (ln_cover - ln_w).exp();
                        }
                    }
                }
                for p in &mut posterior {
                    *p /= total;
                }
            }
        }
        Ok(posterior)
    }
}

#[cfg(test)]
mod tests {
    use crate::event::{Field, Mix, Observe};
    use crate::filter::PropertyFilter;
    use crate::radon::RadonBelief;
    use crate::track_set::TrackSet;

    fn set(t: &[u32]) -> TrackSet {
        TrackSet::from_tracks(t.iter().copied())
    }

    /// The example of Table I (0-based): {0,1} red, tracks 0,2 then 2,3 mix,
    /// then track 2 is seen red for certain: the belief resolves to {1,2}.
    #[test]
    fn table_i_final_observation_resolves_to_tracks_2_and_3() {
        let mut belief = RadonBelief::new(Field::known(4, vec![0, 1])).unwrap();
        belief
            .mix(Mix {
                a: 0,
                b: 2,
                swap: 0.5,
            })
            .unwrap();
        belief
            .mix(Mix {
                a: 2,
                b: 3,
                swap: 0.5,
            })
            .unwrap();
        belief
            .observe(Observe {
                track: 2,
                red: 1.0,
                blue: 0.0,
            })
            .unwrap();
        let p = belief.marginals().unwrap();
        let expect = [0.0, 1.0, 1.0, 0.0];
        for (got, want) in p.iter().zip(expect) {
            assert!((got - want).abs() < 1e-12, "{p:?}");
        }
        assert_eq!(belief.predicted_red().unwrap(), vec![1, 2]);
        assert!((belief.prob_all_red(&set(&[1, 2])).unwrap() - 1.0).abs() < 1e-12);
        // Before the observation {1,2} had f = ¼ of a total of 1.
        assert!((belief.log_normalizer() - 0.25f64.ln()).abs() < 1e-12);
    }

    /// Example 4.1: at t = 2 the distribution is c1 = [0, ¼, 0, 0] and
    /// c2 = ¼ on {1,2}; its marginals are those of Table II's last row.
    #[test]
    fn example_4_1_lower_order_representation() {
        let field = Field::uniform(4, 2);
        let belief = RadonBelief::from_coefficients(
            field,
            Default::default(),
            [(set(&[1]), 0.25), (set(&[0, 1]), 0.25)],
        )
        .unwrap();
        // Table II, f(x^(2)): {1,2}: ½, {2,3}: ¼, {2,4}: ¼ (paper's 1-based ids).
        assert!((belief.prob_all_red(&set(&[0, 1])).unwrap() - 0.5).abs() < 1e-12);
        assert!((belief.prob_all_red(&set(&[1, 2])).unwrap() - 0.25).abs() < 1e-12);
        assert!((belief.prob_all_red(&set(&[1, 3])).unwrap() - 0.25).abs() < 1e-12);
        assert!(belief.prob_all_red(&set(&[0, 2])).unwrap().abs() < 1e-12);
        let p = belief.marginals().unwrap();
        let expect = [0.5, 1.0, 0.25, 0.25];
        for (got, want) in p.iter().zip(expect) {
            assert!((got - want).abs() < 1e-12, "{p:?}");
        }
    }

    #[test]
    fn unknown_count_posterior_moves_with_evidence() {
        let field = Field {
            tracks: 3,
            red: crate::event::RedCount::unknown_uniform(3),
            initial_red: None,
        };
        let mut belief = RadonBelief::new(field).unwrap();
        let before = belief.count_posterior().unwrap();
        for p in &before {
            assert!((p - 0.25).abs() < 1e-12);
        }
        for t in 0..3 {
            belief
                .observe(Observe {
                    track: t,
                    red: 0.9,
                    blue: 0.1,
                })
                .unwrap();
        }
        let after = belief.count_posterior().unwrap();
        assert!(after[3] > 0.7, "{after:?}");
        assert!((after.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        let p = belief.marginals().unwrap();
        assert!(p.iter().all(|x| *x > 0.8));
    }
}
