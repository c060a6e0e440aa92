//! From a classifier's class scores to the likelihoods of an `observe`
//! line (the paper's Section 3.4: an observation is a pair of likelihoods,
//! one if the target is red, one if it is blue).
//!
//! Read a score s of the property's label (e.g. `red`) as the classifier's
//! probability that the target has the property, under even odds. Then
//! the likelihood ratio of the observation is s / (1 − s). Classifiers are
//! rarely calibrated — a network trained with cross-entropy is usually
//! overconfident — so the ratio is tempered with a temperature T:
//!
//! ```text
//! red  ∝ s^(1/T)        blue ∝ (1 − s)^(1/T)        (normalised to sum 1)
//! ```
//!
//! which is temperature scaling of the logit: the calibrated probability
//! is σ(logit(s) / T). T = 1 takes the scores at their word, T > 1 softens
//! an overconfident classifier. Scores are clamped to [1e-6, 1 − 1e-6]
//! first: a classifier's 1.0 would otherwise make the other colour
//! impossible for ever, and one wrong certainty would ruin the belief.
//! Labels other than the property's all count as "not the property".
//!
//! Calibrate T with [`ScoreMapping::fit`] on detections whose true class
//! is known: the maximum-likelihood temperature (a one-parameter logistic
//! regression on the logit, solved by Newton's method).

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

use crate::meetings::CalibrationError;

/// Score clamp, see the module docs.
const SCORE_FLOOR: f64 = 1e-6;

/// The label that means "red" (the property) and the temperature.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ScoreMapping {
    /// The class label of the property, e.g. `red`.
    pub label: String,
    /// T > 0; 1 takes the scores as calibrated.
    pub temperature: f64,
}

impl Default for ScoreMapping {
    fn default() -> Self {
        ScoreMapping {
            label: "red".into(),
            temperature: 1.0,
        }
    }
}

impl ScoreMapping {
    pub fn validate(&self) -> Result<(), CalibrationError> {
        if !(self.temperature.is_finite() && self.temperature > 0.0) {
            return Err(CalibrationError::Invalid(format!(
                "temperature must be finite and > 0, got {}",
                self.temperature
            )));
        }
        if self.label.is_empty() {
            return Err(CalibrationError::Invalid(
                "the property's label is empty".into(),
            ));
        }
        Ok(())
    }

    /// The property's score in `scores` (0 when the label is absent).
    pub(crate) fn score(&self, scores: &BTreeMap<String, f64>) -> f64 {
        scores.get(&self.label).copied().unwrap_or(0.0)
    }

    /// The (red, blue) likelihoods of an observation with these scores,
    /// summing to 1, both > 0.
    pub(crate) fn likelihoods(&self, scores: &BTreeMap<String, f64>) -> (f64, f64) {
        let s = self.score(scores).clamp(SCORE_FLOOR, 1.0 - SCORE_FLOOR);
        // Through the logit, so a high temperature cannot underflow both.
        let z = (s / (1.0 - s)).ln() / self.temperature;
        let red = 1.0 / (1.0 + (-z).exp());
        (red, 1.0 - red)
    }

    /// The maximum-likelihood temperature for the property's `label`, from
    /// (score of the label, whether the target truly had the property)
    /// pairs. Fails without samples, or when the scores carry no
    /// information or point the wrong way (no positive temperature fits).
    #[cfg(test)]
    pub(crate) fn fit(
        label: &str,
        samples: &[(f64, bool)],
    ) -> Result<ScoreMapping, CalibrationError> {
        if samples.is_empty() {
            return Err(CalibrationError::NoSamples);
        }
        let data: Vec<(f64, f64)> = samples
            .iter()
            .map(|&(s, truth)| {
                let s = s.clamp(SCORE_FLOOR, 1.0 - SCORE_FLOOR);
                ((s / (1.0 - s)).ln(), if truth { 1.0 } else { 0.0 })
            })
            .collect();
        // Newton on u = 1/T: the negative log-likelihood of
        // y ~ Bernoulli(σ(u z)) is convex in u.
        let mut u = 1.0f64;
        for _ in 0..100 {
            let (mut gradient, mut curvature) = (0.0, 0.0);
            for &(z, y) in &data {
                let p = 1.0 / (1.0 + (-u * z).exp());
                gradient += (p - y) * z;
                curvature += p * (1.0 - p) * z * z;
            }
            if curvature <= 1e-300 {
                return Err(CalibrationError::NotIdentifiable(
                    "every score is 0.5: no temperature fits".into(),
                ));
            }
            let step = gradient / curvature;
            // Damped: never more than halve or double u in one step.
            let next = (u - step).clamp(u / 2.0, u * 2.0);
            let done = (next - u).abs() < 1e-12 * u.abs().max(1.0);
            u = next;
            if done {
                break;
            }
            if u < 1e-6 {
                return Err(CalibrationError::NotIdentifiable(
                    "the scores carry no information about the label, or point the wrong way"
                        .into(),
                ));
            }
        }
        Ok(ScoreMapping {
            label: label.to_string(),
            temperature: 1.0 / u,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn scores(red: f64) -> BTreeMap<String, f64> {
        BTreeMap::from([("red".to_string(), red), ("blue".to_string(), 1.0 - red)])
    }

    #[test]
    fn temperature_one_takes_the_scores_at_their_word() {
        let m = ScoreMapping::default();
        let (r, b) = m.likelihoods(&scores(0.83));
        assert!((r - 0.83).abs() < 1e-12 && (b - 0.17).abs() < 1e-12);
        // A certainty is clamped, not kept.
        let (r, b) = m.likelihoods(&scores(1.0));
        assert!(r < 1.0 && b > 0.0);
        // An absent label is a score of 0 (clamped).
        let (r, _) = m.likelihoods(&BTreeMap::from([("blue".to_string(), 1.0)]));
        assert!(r > 0.0 && r < 1e-5);
    }

    #[test]
    fn a_higher_temperature_softens() {
        let hot = ScoreMapping {
            temperature: 2.0,
            ..Default::default()
        };
        let (r, b) = hot.likelihoods(&scores(0.9));
        // Ratio 9 becomes 9^(1/2) = 3.
        assert!((r / b - 3.0).abs() < 1e-9);
        assert!(ScoreMapping {
            temperature: 0.0,
            ..Default::default()
        }
        .validate()
        .is_err());
    }

    #[test]
    fn the_fit_recovers_a_known_temperature() {
        // The classifier's logit is 2.5 times the true one: overconfident,
        // so the right temperature is 2.5.
        let t0 = 2.5;
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let samples: Vec<(f64, bool)> = (0..20_000)
            .map(|_| {
                let z: f64 = rng.gen_range(-3.0..3.0);
                let truth = rng.gen::<f64>() < 1.0 / (1.0 + (-z).exp());
                let reported = 1.0 / (1.0 + (-z * t0).exp());
                (reported, truth)
            })
            .collect();
        let fitted = ScoreMapping::fit("red", &samples).unwrap();
        assert!(
            (fitted.temperature - t0).abs() < 0.1,
            "fitted {}",
            fitted.temperature
        );
        assert_eq!(
            ScoreMapping::fit("red", &[]),
            Err(CalibrationError::NoSamples)
        );
        // Scores that point the wrong way have no positive temperature.
        let wrong: Vec<(f64, bool)> = (0..100).map(|i| (0.9, i % 10 == 0)).collect();
        assert!(ScoreMapping::fit("red", &wrong).is_err());
    }
}
