//! Seeded random identity event streams with a ground truth, for tests and
//! benchmarks: the shape of the simulations of Shin et al. (IPSN 2005,
//! Section 5.1 — a stream of mixing and evidence events with a fixed ratio
//! of the two) without a motion model.
//!
//! The truth starts from a random assignment (returned, so a filter may
//! start from it or from the uniform prior). A mix of tracks a and b swaps
//! their targets with probability `swap`, exactly as the filters model it;
//! a read returns the true identity with probability `accuracy` and
//! otherwise one of the N − 1 others uniformly — the [`Identify`] model. So
//! the exact filter is the exact posterior of these streams.

use super::event::{Identify, IdentityEvent};
use idmesh_belief::BeliefError;
use idmesh_belief::Mix;
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// What kind of stream to draw.
#[derive(Debug, Clone, PartialEq)]
pub struct IdentityWorkloadSpec {
    /// N tracks = N identities (≥ 1).
    pub tracks: usize,
    pub events: usize,
    /// Share of events that are mixes, in [0, 1] (the paper's figures vary
    /// the ratio of mixes to reads; ratio r is share r/(1 + r)).
    pub mix_share: f64,
    /// Swap probability of every mix, in [0, 1].
    pub swap: f64,
    /// Accuracy of every read, in (0, 1].
    pub accuracy: f64,
    /// Mixes pair tracks at most this far apart in id (targets that are
    /// close in the field); `tracks` = any pair.
    pub neighbourhood: usize,
    pub seed: u64,
}

impl IdentityWorkloadSpec {
    /// The paper's simulations: fifty events with the 0.9 read model and
    /// mixes of any two tracks with α = ½, `ratio` mixes per read.
    pub fn paper(tracks: usize, ratio: f64, seed: u64) -> Self {
        IdentityWorkloadSpec {
            tracks,
            events: 50,
            mix_share: ratio / (1.0 + ratio),
            swap: 0.5,
            accuracy: 0.9,
            neighbourhood: tracks,
            seed,
        }
    }

    /// Checks the spec.
    pub fn validate(&self) -> Result<(), BeliefError> {
        if self.tracks == 0 {
            return Err(BeliefError::NoTracks);
        }
        if !(0.0..=1.0).contains(&self.swap) {
            return Err(BeliefError::BadSwap { swap: self.swap });
        }
        if !(self.accuracy > 0.0 && self.accuracy <= 1.0) {
            return Err(BeliefError::BadAccuracy {
                accuracy: self.accuracy,
            });
        }
        if !(0.0..=1.0).contains(&self.mix_share) {
            return Err(BeliefError::Unsupported {
                method: "identity workload",
                what: "a mix share outside [0, 1]",
            });
        }
        Ok(())
    }
}

/// A drawn stream: the true assignment at time 0 (`initial[t]` = identity
/// on track t), the events, and the true assignment after every event.
#[derive(Debug, Clone, PartialEq)]
pub struct IdentityWorkload {
    pub initial: Vec<u32>,
    pub events: Vec<IdentityEvent>,
    pub truth: Vec<Vec<u32>>,
}

/// Draws a stream; the same spec always gives the same stream.
pub fn generate(spec: &IdentityWorkloadSpec) -> Result<IdentityWorkload, BeliefError> {
    let mut history = Vec::with_capacity(spec.events);
    let (initial, events) = generate_with(spec, |truth| history.push(truth.to_vec()))?;
    Ok(IdentityWorkload {
        initial,
        events,
        truth: history,
    })
}

/// The initial assignment, the events and the final assignment.
pub(crate) type FinalWorkload = (Vec<u32>, Vec<IdentityEvent>, Vec<u32>);

/// A stream too large to keep the truth after every event (n = 10,000):
/// the true assignment at time 0, the events, and the true assignment at
/// the end.
pub fn generate_final(spec: &IdentityWorkloadSpec) -> Result<FinalWorkload, BeliefError> {
    let mut last = Vec::new();
    let (initial, events) = generate_with(spec, |truth| {
        last.clear();
        last.extend_from_slice(truth)
    })?;
    if events.is_empty() {
        last = initial.clone();
    }
    Ok((initial, events, last))
}

/// Draws the stream, calling `after` with the truth after every event.
fn generate_with(
    spec: &IdentityWorkloadSpec,
    mut after: impl FnMut(&[u32]),
) -> Result<(Vec<u32>, Vec<IdentityEvent>), BeliefError> {
    spec.validate()?;
    let mut rng = ChaCha8Rng::seed_from_u64(spec.seed);
    let n = spec.tracks;
    let mut truth: Vec<u32> = (0..n as u32).collect();
    truth.shuffle(&mut rng);
    let initial = truth.clone();
    let mut events = Vec::with_capacity(spec.events);
    for _ in 0..spec.events {
        // With one track there is nothing to mix: every event is a read.
        if n >= 2 && rng.gen::<f64>() < spec.mix_share {
            let a = rng.gen_range(0..n);
            let reach = spec.neighbourhood.clamp(1, n - 1);
            let b = (a + rng.gen_range(1..=reach)) % n;
            if rng.gen::<f64>() < spec.swap {
                truth.swap(a, b);
            }
            events.push(IdentityEvent::Mix(Mix {
                a: a as u32,
                b: b as u32,
                swap: spec.swap,
            }));
        } else {
            let t = rng.gen_range(0..n);
            let identity = if n == 1 || rng.gen::<f64>() < spec.accuracy {
                truth[t]
            } else {
                // A wrong read: one of the n − 1 other identities.
                let k = rng.gen_range(0..n as u32 - 1);
                if k >= truth[t] {
                    k + 1
                } else {
                    k
                }
            };
            events.push(IdentityEvent::Identify(Identify {
                track: t as u32,
                identity,
                accuracy: spec.accuracy,
            }));
        }
        after(&truth);
    }
    Ok((initial, events))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn deterministic_and_consistent() {
        let spec = IdentityWorkloadSpec {
            events: 2000,
            ..IdentityWorkloadSpec::paper(6, 1.0, 3)
        };
        let a = generate(&spec).unwrap();
        assert_eq!(a, generate(&spec).unwrap());
        assert_eq!(a.truth.len(), 2000);
        let mut reads = 0;
        let mut right = 0;
        let mut mixes = 0;
        let mut truth = a.initial.clone();
        for (e, after) in a.events.iter().zip(&a.truth) {
            match e {
                IdentityEvent::Mix(m) => {
                    mixes += 1;
                    // The truth changes only by swapping the mixed pair.
                    let (x, y) = (m.a as usize, m.b as usize);
                    let swapped = {
                        let mut s = truth.clone();
                        s.swap(x, y);
                        s
                    };
                    assert!(*after == truth || *after == swapped);
                }
                IdentityEvent::Identify(r) => {
                    reads += 1;
                    assert_eq!(*after, truth);
                    right += usize::from(truth[r.track as usize] == r.identity);
                }
            }
            truth = after.clone();
        }
        assert!((900..1100).contains(&mixes), "{mixes}");
        let rate = right as f64 / reads as f64;
        assert!((rate - 0.9).abs() < 0.04, "{rate}");
    }

    #[test]
    fn refuses_bad_specs() {
        let good = IdentityWorkloadSpec::paper(4, 1.0, 0);
        for bad in [
            IdentityWorkloadSpec {
                tracks: 0,
                ..good.clone()
            },
            IdentityWorkloadSpec {
                accuracy: 0.0,
                ..good.clone()
            },
            IdentityWorkloadSpec {
                swap: 1.5,
                ..good.clone()
            },
            IdentityWorkloadSpec {
                mix_share: -0.1,
                ..good.clone()
            },
        ] {
            assert!(generate(&bad).is_err());
        }
        let one = generate(&IdentityWorkloadSpec::paper(1, 1.0, 0)).unwrap();
        assert!(one
            .events
            .iter()
            .all(|e| matches!(e, IdentityEvent::Identify(r) if r.identity == 0)));
    }
}
