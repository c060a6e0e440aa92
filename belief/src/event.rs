//! The events every filter consumes, and the description of a field every
//! filter starts from. These mirror the `mix` and `observe` lines of the
//! trace format (shared/spec/trace.md) but carry no I/O concerns: the engine
//! checks only what it needs to stay sound.

use crate::error::BeliefError;

/// Targets on tracks `a` and `b` came close; with probability `swap` they
/// exchanged tracks (the paper's 1 − p, Section 3.3).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Mix {
    pub a: u32,
    pub b: u32,
    pub swap: f64,
}

/// A sensor saw the property of the target on `track`: `red` is the
/// likelihood of the observation if that target is red, `blue` if it is blue
/// (Section 3.4; the likelihood b·φ_∅ + (a − b)·φ_{track}).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observe {
    pub track: u32,
    pub red: f64,
    pub blue: f64,
}

/// One event for a property belief.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Event {
    Mix(Mix),
    Observe(Observe),
}

/// How many targets are red.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum RedCount {
    /// Exactly `k` of the tracks carry red targets.
    Known(usize),
    /// Unknown: `prior[j]` is the prior probability that exactly `j` of the
    /// `n` tracks are red (length n + 1). See [`RedCount::unknown_uniform`].
    Unknown { prior: Vec<f64> },
}

impl RedCount {
    /// Every count 0..=n equally likely, and given the count every set of
    /// that size equally likely: the least committal prior when the trace
    /// header has no `red`.
    pub fn unknown_uniform(tracks: usize) -> Self {
        RedCount::Unknown {
            prior: vec![1.0 / (tracks as f64 + 1.0); tracks + 1],
        }
    }

    /// The known count, if any.
    pub fn known(&self) -> Option<usize> {
        match self {
            RedCount::Known(k) => Some(*k),
            RedCount::Unknown { .. } => None,
        }
    }
}

/// What a property filter starts from: n tracks, how many are red, and
/// either the known red tracks at time 0 or the uniform prior.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Field {
    pub tracks: usize,
    pub red: RedCount,
    /// The red tracks at time 0; `None` = uniform over all allowed sets.
    pub initial_red: Option<Vec<u32>>,
}

impl Field {
    /// k known, uniform prior over the k-sets.
    pub fn uniform(tracks: usize, k: usize) -> Self {
        Field {
            tracks,
            red: RedCount::Known(k),
            initial_red: None,
        }
    }

    /// k known and the red tracks at time 0 known.
    pub fn known(tracks: usize, initial_red: Vec<u32>) -> Self {
        Field {
            tracks,
            red: RedCount::Known(initial_red.len()),
            initial_red: Some(initial_red),
        }
    }

    /// The field a trace header or a stream's `Begin` describes: k known
    /// (`red`) or unknown with the uniform prior over counts
    /// ([`RedCount::unknown_uniform`]), and the red tracks at time 0 when
    /// given. The one place `idmesh replay` and the leaders turn a count
    /// into a field, so both start from the same belief.
    pub fn with_count(tracks: usize, red: Option<usize>, initial_red: Option<Vec<u32>>) -> Self {
        Field {
            tracks,
            red: match red {
                Some(k) => RedCount::Known(k),
                None => RedCount::unknown_uniform(tracks),
            },
            initial_red,
        }
    }

    /// Checks the field is consistent; every filter calls this first.
    pub fn validate(&self) -> Result<(), BeliefError> {
        if self.tracks == 0 {
            return Err(BeliefError::NoTracks);
        }
        match &self.red {
            RedCount::Known(k) if *k > self.tracks => {
                return Err(BeliefError::TooManyRed {
                    red: *k,
                    tracks: self.tracks,
                })
            }
            RedCount::Known(_) => {}
            RedCount::Unknown { prior } => {
                let ok = prior.len() == self.tracks + 1
                    && prior.iter().all(|p| p.is_finite() && *p >= 0.0)
                    && prior.iter().sum::<f64>() > 0.0;
                if !ok {
                    return Err(BeliefError::BadCountPrior {
                        expected: self.tracks + 1,
                    });
                }
            }
        }
        if let Some(initial) = &self.initial_red {
            let mut sorted = initial.clone();
            sorted.sort_unstable();
            sorted.dedup();
            let size_ok = match &self.red {
                RedCount::Known(k) => initial.len() == *k,
                RedCount::Unknown { prior } => prior.get(initial.len()).is_some_and(|p| *p > 0.0),
            };
            if sorted.len() != initial.len()
                || !size_ok
                || sorted.iter().any(|&t| t as usize >= self.tracks)
            {
                return Err(BeliefError::BadInitialRed {
                    expected: self.red.known().unwrap_or(initial.len()),
                    got: initial.clone(),
                });
            }
        }
        Ok(())
    }

    /// Checks one event against this field.
    pub(crate) fn check(&self, event: &Event) -> Result<(), BeliefError> {
        match *event {
            Event::Mix(mix) => self.check_mix(&mix),
            Event::Observe(observe) => self.check_observe(&observe),
        }
    }

    pub(crate) fn check_mix(&self, mix: &Mix) -> Result<(), BeliefError> {
        self.check_track(mix.a)?;
        self.check_track(mix.b)?;
        if mix.a == mix.b {
            return Err(BeliefError::SelfMix { track: mix.a });
        }
        if !(0.0..=1.0).contains(&mix.swap) {
            return Err(BeliefError::BadSwap { swap: mix.swap });
        }
        Ok(())
    }

    pub(crate) fn check_observe(&self, observe: &Observe) -> Result<(), BeliefError> {
        self.check_track(observe.track)?;
        let valid = |x: f64| x.is_finite() && x >= 0.0;
        if !valid(observe.red)
            || !valid(observe.blue)
            || (observe.red == 0.0 && observe.blue == 0.0)
        {
            return Err(BeliefError::BadLikelihood {
                red: observe.red,
                blue: observe.blue,
            });
        }
        Ok(())
    }

    pub(crate) fn check_track(&self, track: u32) -> Result<(), BeliefError> {
        if (track as usize) < self.tracks {
            Ok(())
        } else {
            Err(BeliefError::UnknownTrack {
                track,
                tracks: self.tracks,
            })
        }
    }
}
