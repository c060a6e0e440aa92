//! Seeded random event streams with a ground truth, for property tests and
//! benchmarks: the shape of the paper's Table III workload (n tracks, k red,
//! a share of mixing events, the colour-histogram sensor of the trace spec)
//! without a motion model. The scenario generator of the `sensor` crate makes
//! realistic streams from simulated and real motion; this one only needs to
//! be cheap, deterministic and cover the corner cases.

use crate::event::{Event, Mix, Observe};
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// What kind of stream to draw.
#[derive(Debug, Clone, PartialEq)]
pub struct WorkloadSpec {
    pub tracks: usize,
    pub red: usize,
    pub events: usize,
    /// Share of events that are mixes, in [0, 1].
    pub mix_share: f64,
    /// Swap probability of every mix.
    pub swap: f64,
    /// Mixes pair tracks at most this far apart in id (targets that are
    /// close in the field); `tracks` = any pair.
    pub neighbourhood: usize,
    pub seed: u64,
}

impl WorkloadSpec {
    /// The Table III workload: 1000 events, half of them mixes.
    pub fn table3(tracks: usize, seed: u64) -> Self {
        WorkloadSpec {
            tracks,
            red: tracks / 2,
            events: 1000,
            mix_share: 0.5,
            swap: 0.5,
            neighbourhood: 4,
            seed,
        }
    }
}

/// A drawn stream: the true red tracks at time 0, the events, and the true
/// red tracks after every event (after every `truth_every`-th event with
/// [`generate_with`]: `truth[i]` follows event `(i + 1)·truth_every − 1`).
#[derive(Debug, Clone)]
pub struct Workload {
    pub initial_red: Vec<u32>,
    pub events: Vec<Event>,
    pub truth: Vec<Vec<u32>>,
}

/// The colour-histogram sensor of the trace spec: a red target shows 80 %
/// red, 10 % blue and 10 % other pixels; a blue one 20 % red, 70 % blue, 10 %
/// other. A pixel of "other" colour says nothing, so the sensor draws again.
pub(crate) fn colour_histogram(rng: &mut impl Rng, is_red: bool) -> (f64, f64) {
    let u: f64 = rng.gen();
    let sees_red = if is_red { u < 0.8 / 0.9 } else { u < 0.2 / 0.9 };
    if sees_red {
        (0.8, 0.2)
    } else {
        (0.1, 0.7)
    }
}

pub fn generate(spec: &WorkloadSpec) -> Workload {
    generate_with(spec, 1)
}

/// As [`generate`], recording the truth only after every `truth_every`-th
/// event (0 = never): long streams on large fields cannot keep it all.
pub fn generate_with(spec: &WorkloadSpec, truth_every: usize) -> Workload {
    let mut rng = ChaCha8Rng::seed_from_u64(spec.seed);
    let n = spec.tracks;
    let mut ids: Vec<u32> = (0..n as u32).collect();
    ids.shuffle(&mut rng);
    let mut red = vec![false; n];
    for &t in &ids[..spec.red] {
        red[t as usize] = true;
    }
    let initial_red = red_tracks(&red);
    let mut events = Vec::with_capacity(spec.events);
    let mut truth = Vec::with_capacity(spec.events);
    for _ in 0..spec.events {
        if n >= 2 && rng.gen::<f64>() < spec.mix_share {
            let a = rng.gen_range(0..n);
            let reach = spec.neighbourhood.clamp(1, n - 1);
            let step = rng.gen_range(1..=reach);
            let b = (a + step) % n;
            if rng.gen::<f64>() < spec.swap {
                red.swap(a, b);
            }
            events.push(Event::Mix(Mix {
                a: a as u32,
                b: b as u32,
                swap: spec.swap,
            }));
        } else {
            let t = rng.gen_range(0..n);
            let (r, b) = colour_histogram(&mut rng, red[t]);
            events.push(Event::Observe(Observe {
                track: t as u32,
                red: r,
                blue: b,
            }));
        }
        if truth_every > 0 && events.len() % truth_every == 0 {
            truth.push(red_tracks(&red));
        }
    }
    Workload {
        initial_red,
        events,
        truth,
    }
}

fn red_tracks(red: &[bool]) -> Vec<u32> {
    (0..red.len() as u32).filter(|&t| red[t as usize]).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn deterministic_and_consistent() {
        let spec = WorkloadSpec::table3(20, 7);
        let a = generate(&spec);
        let b = generate(&spec);
        assert_eq!(a.events, b.events);
        assert_eq!(a.initial_red.len(), 10);
        assert!(a.truth.iter().all(|t| t.len() == 10));
        let mixes = a
            .events
            .iter()
            .filter(|e| matches!(e, Event::Mix(_)))
            .count();
        assert!((400..600).contains(&mixes), "{mixes}");
    }
}
