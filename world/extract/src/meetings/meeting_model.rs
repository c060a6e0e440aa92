//! The swap probability of a meeting: the chance that the tracker leaves a
//! meeting with the two targets exchanged (the paper's 1 − p of a mixing
//! event, Section 6; the `swap` of a `mix` line).
//!
//! - [`MeetingModel::Constant`]`(p)` — every meeting swaps with
//!   probability p (what the simulator and the paper's evaluation use).
//! - [`MeetingModel::Approach`] — a tracker confuses two people more the
//!   closer they come, and less the faster they pass each other (a quick
//!   crossing is told apart by motion continuity; two people who stop
//!   together are not):
//!
//!   ```text
//!   swap = p_max · exp(−c² / (2 σ²)) · v₀ / (v₀ + v)
//!   ```
//!
//!   with c the predicted closest distance of the meeting (metres), v the
//!   relative speed (m/s) — see [`Meeting`] — and the parameters p_max (the
//!   swap probability of a standing, touching pair, ≤ 1), σ (metres: how
//!   fast confusion falls with distance) and v₀ (m/s: the relative speed
//!   at which confusion halves).
//!
//! Calibrate [`MeetingModel::Approach`] on meetings whose outcome is known
//! (a tracker run on annotated video: did the tracker swap the two
//! identities?) with [`MeetingModel::fit_approach`], a maximum-likelihood
//! grid search over σ and v₀ for a given p_max.

use super::meeting::Meeting;
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// How likely a meeting is to swap its two tracks' targets.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MeetingModel {
    /// Every meeting swaps with this probability.
    Constant(f64),
    /// Swap probability from the closest distance and relative speed (the
    /// formula of the module docs).
    Approach { p_max: f64, sigma: f64, v0: f64 },
}

impl Default for MeetingModel {
    /// The simulator's default: a meeting is a coin toss.
    fn default() -> Self {
        MeetingModel::Constant(0.5)
    }
}

/// Why a model or its fit is unusable.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum CalibrationError {
    #[error("{0}")]
    Invalid(String),
    #[error("no labelled samples to calibrate on")]
    NoSamples,
    #[error("the samples do not fix the parameter: {0}")]
    NotIdentifiable(String),
}

impl MeetingModel {
    /// Checks the parameters.
    pub fn validate(&self) -> Result<(), CalibrationError> {
        let bad = |s: String| Err(CalibrationError::Invalid(s));
        match *self {
            MeetingModel::Constant(p) if !(0.0..=1.0).contains(&p) => {
                bad(format!("swap probability must be in [0, 1], got {p}"))
            }
            MeetingModel::Approach { p_max, .. } if !(0.0..=1.0).contains(&p_max) => {
                bad(format!("p_max must be in [0, 1], got {p_max}"))
            }
            MeetingModel::Approach { sigma, .. } if !(sigma.is_finite() && sigma > 0.0) => {
                bad(format!("sigma must be finite and > 0, got {sigma}"))
            }
            MeetingModel::Approach { v0, .. } if !(v0.is_finite() && v0 > 0.0) => {
                bad(format!("v0 must be finite and > 0, got {v0}"))
            }
            _ => Ok(()),
        }
    }

    /// The swap probability of `meeting`, in [0, 1].
    pub fn swap(&self, meeting: &Meeting) -> f64 {
        match *self {
            MeetingModel::Constant(p) => p,
            MeetingModel::Approach { p_max, sigma, v0 } => {
                approach(p_max, sigma, v0, meeting.closest, meeting.relative_speed)
            }
        }
    }

    /// Fits σ and v₀ of [`MeetingModel::Approach`] for a given `p_max` to
    /// meetings labelled with whether the tracker swapped them: the pair
    /// that maximises the Bernoulli log-likelihood on a log grid (σ from
    /// 2 cm to 10 m, v₀ from 2 cm/s to 20 m/s), refined once around the
    /// best cell.
    pub(crate) fn fit_approach(
        p_max: f64,
        samples: &[(Meeting, bool)],
    ) -> Result<MeetingModel, CalibrationError> {
        MeetingModel::fit_approach_on_grid(p_max, samples, 48)
    }

    /// [`MeetingModel::fit_approach`] with `steps` grid steps a side.
    fn fit_approach_on_grid(
        p_max: f64,
        samples: &[(Meeting, bool)],
        steps: usize,
    ) -> Result<MeetingModel, CalibrationError> {
        MeetingModel::Approach {
            p_max,
            sigma: 1.0,
            v0: 1.0,
        }
        .validate()?;
        if samples.is_empty() {
            return Err(CalibrationError::NoSamples);
        }
        if !samples.iter().any(|(_, swapped)| *swapped) {
            return Err(CalibrationError::NotIdentifiable(
                "no meeting swapped: sigma would go to 0".into(),
            ));
        }
        let log_likelihood = |sigma: f64, v0: f64| -> f64 {
            MeetingModel::Approach { p_max, sigma, v0 }.log_likelihood(samples)
        };
        let (mut lo_s, mut hi_s) = (0.02f64.ln(), 10f64.ln());
        let (mut lo_v, mut hi_v) = (0.02f64.ln(), 20f64.ln());
        let mut best = (f64::NEG_INFINITY, 1.0, 1.0);
        for _round in 0..2 {
            let (ds, dv) = ((hi_s - lo_s) / steps as f64, (hi_v - lo_v) / steps as f64);
            for i in 0..=steps {
                let sigma = (lo_s + ds * i as f64).exp();
                for j in 0..=steps {
                    let v0 = (lo_v + dv * j as f64).exp();
                    let ll = log_likelihood(sigma, v0);
                    if ll > best.0 {
                        best = (ll, sigma, v0);
                    }
                }
            }
            // Zoom in on two cells either side of the best.
            let (s, v) = (best.1.ln(), best.2.ln());
            (lo_s, hi_s) = (s - 2.0 * ds, s + 2.0 * ds);
            (lo_v, hi_v) = (v - 2.0 * dv, v + 2.0 * dv);
        }
        Ok(MeetingModel::Approach {
            p_max,
            sigma: best.1,
            v0: best.2,
        })
    }
}

impl MeetingModel {
    /// The Bernoulli log-likelihood of meetings labelled with whether the
    /// tracker swapped them (probabilities clamped to [1e-12, 1 − 1e-12]).
    pub(crate) fn log_likelihood(&self, samples: &[(Meeting, bool)]) -> f64 {
        samples
            .iter()
            .map(|(m, swapped)| {
                let p = self.swap(m).clamp(1e-12, 1.0 - 1e-12);
                if *swapped {
                    p.ln()
                } else {
                    (1.0 - p).ln()
                }
            })
            .sum()
    }

    /// Fits all three parameters of [`MeetingModel::Approach`]: p_max on
    /// a grid of 0.05 steps, each with σ and v₀ fitted on a coarse grid;
    /// then σ and v₀ of the most likely p_max as
    /// [`MeetingModel::fit_approach`] does.
    pub fn fit_approach_all(samples: &[(Meeting, bool)]) -> Result<MeetingModel, CalibrationError> {
        let mut best: Option<(f64, f64)> = None;
        for step in 1..=20 {
            let p_max = step as f64 * 0.05;
            let ll =
                MeetingModel::fit_approach_on_grid(p_max, samples, 16)?.log_likelihood(samples);
            if best.is_none_or(|(b, _)| ll > b) {
                best = Some((ll, p_max));
            }
        }
        MeetingModel::fit_approach(best.expect("twenty candidates").1, samples)
    }

    /// The maximum-likelihood [`MeetingModel::Constant`]: the share of
    /// meetings that swapped.
    pub fn fit_constant(samples: &[(Meeting, bool)]) -> Result<MeetingModel, CalibrationError> {
        if samples.is_empty() {
            return Err(CalibrationError::NoSamples);
        }
        let swapped = samples.iter().filter(|(_, s)| *s).count();
        Ok(MeetingModel::Constant(
            swapped as f64 / samples.len() as f64,
        ))
    }
}

fn approach(p_max: f64, sigma: f64, v0: f64, closest: f64, speed: f64) -> f64 {
    p_max * (-closest * closest / (2.0 * sigma * sigma)).exp() * v0 / (v0 + speed)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn meeting(closest: f64, relative_speed: f64) -> Meeting {
        Meeting {
            time: 0.0,
            a: 0,
            b: 1,
            distance: closest.max(0.5),
            closest,
            relative_speed,
        }
    }

    #[test]
    fn constant_is_constant() {
        let m = MeetingModel::Constant(0.3);
        assert_eq!(m.swap(&meeting(0.0, 0.0)), 0.3);
        assert_eq!(m.swap(&meeting(0.9, 3.0)), 0.3);
        assert!(MeetingModel::Constant(1.5).validate().is_err());
    }

    #[test]
    fn approach_follows_its_formula() {
        let m = MeetingModel::Approach {
            p_max: 0.5,
            sigma: 0.5,
            v0: 1.0,
        };
        assert_eq!(m.swap(&meeting(0.0, 0.0)), 0.5);
        // One sigma away: e^(−1/2); at v = v0: one half.
        let want = 0.5 * (-0.5f64).exp() * 0.5;
        assert!((m.swap(&meeting(0.5, 1.0)) - want).abs() < 1e-12);
        assert!(m.swap(&meeting(0.2, 0.0)) > m.swap(&meeting(0.4, 0.0)));
        assert!(m.swap(&meeting(0.2, 0.5)) > m.swap(&meeting(0.2, 2.0)));
        for bad in [
            MeetingModel::Approach {
                p_max: 0.5,
                sigma: 0.0,
                v0: 1.0,
            },
            MeetingModel::Approach {
                p_max: 0.5,
                sigma: 1.0,
                v0: -1.0,
            },
            MeetingModel::Approach {
                p_max: 1.1,
                sigma: 1.0,
                v0: 1.0,
            },
        ] {
            assert!(bad.validate().is_err(), "{bad:?}");
        }
    }

    #[test]
    fn the_fit_recovers_known_parameters() {
        let truth = MeetingModel::Approach {
            p_max: 0.6,
            sigma: 0.4,
            v0: 0.8,
        };
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let samples: Vec<(Meeting, bool)> = (0..6000)
            .map(|_| {
                let m = meeting(rng.gen_range(0.0..1.0), rng.gen_range(0.0..3.0));
                let swapped = rng.gen::<f64>() < truth.swap(&m);
                (m, swapped)
            })
            .collect();
        let MeetingModel::Approach { sigma, v0, .. } =
            MeetingModel::fit_approach(0.6, &samples).unwrap()
        else {
            panic!("not an approach model")
        };
        assert!((sigma - 0.4).abs() < 0.06, "sigma {sigma}");
        assert!((v0 - 0.8).abs() < 0.25, "v0 {v0}");
        assert_eq!(
            MeetingModel::fit_approach(0.6, &[]),
            Err(CalibrationError::NoSamples)
        );
        // All three at once: p_max too.
        let MeetingModel::Approach { p_max, sigma, .. } =
            MeetingModel::fit_approach_all(&samples).unwrap()
        else {
            panic!("not an approach model")
        };
        assert!((p_max - 0.6).abs() < 0.1, "p_max {p_max}");
        assert!((sigma - 0.4).abs() < 0.08, "sigma {sigma}");
        let MeetingModel::Constant(rate) = MeetingModel::fit_constant(&samples).unwrap() else {
            panic!("not a constant")
        };
        let swapped = samples.iter().filter(|(_, s)| *s).count() as f64;
        assert_eq!(rate, swapped / 6000.0);
    }
}
