//! What an observation of a target reports (the paper's likelihood
//! function, Section 3.4 and the sensitivity study of Section 6, Fig. 6).
//!
//! A sensor model is a small table of outcomes. Each outcome has a
//! probability for a red and for a blue target; an outcome that reports
//! writes exactly those two probabilities as the `observe` line's `red` and
//! `blue` likelihoods, so the trace is calibrated: the filter's likelihoods
//! are the generator's. An outcome that does not report (the "other" pixels
//! of the colour histogram) produces no event.

use rand::Rng;

/// One possible result of looking at a target.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct SensorOutcome {
    /// A short name, for messages ("sees red").
    pub name: String,
    /// Probability of this outcome when the target is red ...
    pub if_red: f64,
    /// ... and when it is blue.
    pub if_blue: f64,
    /// Whether the outcome becomes an `observe` event.
    pub reports: bool,
}

/// A table of outcomes; for each colour their probabilities sum to 1.
#[derive(Debug, Clone, PartialEq)]
pub struct SensorModel {
    outcomes: Vec<SensorOutcome>,
}

impl Default for SensorModel {
    fn default() -> Self {
        SensorModel::colour_histogram()
    }
}

impl SensorModel {
    /// The colour-histogram model of the trace spec: a red target shows
    /// 80 % red, 10 % blue and 10 % other pixels, a blue one 20 % red, 70 %
    /// blue, 10 % other. Seeing red reports red 0.8 / blue 0.2, seeing blue
    /// reports red 0.1 / blue 0.7, seeing "other" reports nothing.
    pub fn colour_histogram() -> Self {
        SensorModel {
            outcomes: vec![
                outcome("sees red", 0.8, 0.2, true),
                outcome("sees blue", 0.1, 0.7, true),
                outcome("other", 0.1, 0.1, false),
            ],
        }
    }

    /// A sensor that names the right colour with probability `accuracy`
    /// (in [0.5, 1]) and always reports: seeing red reports
    /// red `accuracy` / blue `1 − accuracy`, and the mirror for blue.
    pub fn symmetric(accuracy: f64) -> Result<Self, String> {
        if !(0.5..=1.0).contains(&accuracy) {
            return Err(format!(
                "sensor accuracy must be in [0.5, 1], got {accuracy}"
            ));
        }
        SensorModel::new(vec![
            outcome("sees red", accuracy, 1.0 - accuracy, true),
            outcome("sees blue", 1.0 - accuracy, accuracy, true),
        ])
    }

    /// A model from its outcome table. Every probability must be in
    /// [0, 1], each colour's must sum to 1 (within 1e-9), and every
    /// reporting outcome must have a positive probability for some colour.
    pub(crate) fn new(outcomes: Vec<SensorOutcome>) -> Result<Self, String> {
        if outcomes.is_empty() {
            return Err("a sensor model needs at least one outcome".into());
        }
        for o in &outcomes {
            for p in [o.if_red, o.if_blue] {
                if !(0.0..=1.0).contains(&p) {
                    return Err(format!(
                        "sensor outcome `{}` has probability {p}, not in [0, 1]",
                        o.name
                    ));
                }
            }
            if o.reports && o.if_red == 0.0 && o.if_blue == 0.0 {
                return Err(format!(
                    "sensor outcome `{}` reports likelihoods 0 and 0",
                    o.name
                ));
            }
        }
        let red: f64 = outcomes.iter().map(|o| o.if_red).sum();
        let blue: f64 = outcomes.iter().map(|o| o.if_blue).sum();
        if (red - 1.0).abs() > 1e-9 || (blue - 1.0).abs() > 1e-9 {
            return Err(format!(
                "sensor outcome probabilities must sum to 1 for each colour, got red {red} and blue {blue}"
            ));
        }
        Ok(SensorModel { outcomes })
    }

    /// Looks at a target of the given colour: the reported (red, blue)
    /// likelihoods, or `None` for an outcome that reports nothing. Always
    /// makes exactly one draw from `rng`.
    pub fn observe(&self, rng: &mut impl Rng, is_red: bool) -> Option<(f64, f64)> {
        let u: f64 = rng.gen();
        let mut acc = 0.0;
        let mut chosen = self.outcomes.last().expect("validated non-empty");
        for o in &self.outcomes {
            acc += if is_red { o.if_red } else { o.if_blue };
            if u < acc {
                chosen = o;
                break;
            }
        }
        chosen.reports.then_some((chosen.if_red, chosen.if_blue))
    }
}

fn outcome(name: &str, if_red: f64, if_blue: f64, reports: bool) -> SensorOutcome {
    SensorOutcome {
        name: name.into(),
        if_red,
        if_blue,
        reports,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn colour_histogram_frequencies() {
        let m = SensorModel::colour_histogram();
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let trials = 50_000;
        for (is_red, want) in [(true, [0.8, 0.1, 0.1]), (false, [0.2, 0.7, 0.1])] {
            let mut counts = [0usize; 3];
            for _ in 0..trials {
                match m.observe(&mut rng, is_red) {
                    Some((r, b)) if (r, b) == (0.8, 0.2) => counts[0] += 1,
                    Some((r, b)) if (r, b) == (0.1, 0.7) => counts[1] += 1,
                    Some(other) => panic!("unexpected report {other:?}"),
                    None => counts[2] += 1,
                }
            }
            for (c, w) in counts.iter().zip(want) {
                let f = *c as f64 / trials as f64;
                assert!((f - w).abs() < 0.01, "red={is_red}: {f} vs {w}");
            }
        }
    }

    #[test]
    fn tables_are_validated() {
        assert!(SensorModel::symmetric(0.9).is_ok());
        assert!(SensorModel::symmetric(0.3).is_err());
        assert!(SensorModel::new(vec![outcome("a", 0.5, 0.5, true)]).is_err());
        assert!(SensorModel::new(vec![]).is_err());
        assert!(SensorModel::new(vec![
            outcome("a", 1.0, 0.0, true),
            outcome("b", 0.0, 1.0, true),
        ])
        .is_ok());
        assert!(SensorModel::new(vec![
            outcome("z", 1.0, 1.0, true),
            outcome("n", 0.0, 0.0, true)
        ])
        .is_err());
    }
}
