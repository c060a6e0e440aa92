//! Random *valid* streams: drawn with a hidden truth, so that every event
//! has a positive likelihood under it and the exact filter would never run
//! out of mass. Shared by the valid-stream tests of every belief: the
//! identity beliefs' (idmesh-identity's `tests/common`) include this file
//! for the partners and swap probabilities of their mixes.

use idmesh_belief::{Event, Mix, Observe};
use proptest::prelude::{prop_assert, TestCaseError};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// A neighbour of `a` most of the time (crowds mix locally), anyone else
/// sometimes.
pub fn partner(rng: &mut ChaCha8Rng, n: usize, a: usize) -> usize {
    if rng.gen_bool(0.8) {
        (a + rng.gen_range(1..=4.min(n - 1))) % n
    } else {
        (a + rng.gen_range(1..n)) % n
    }
}

/// A swap probability: exact 0, ½ and 1, near-certainties both ways, and
/// anything.
pub fn swap_probability(rng: &mut ChaCha8Rng) -> f64 {
    match rng.gen_range(0..7) {
        0 => 0.0,
        1 => 1.0,
        2 => 0.5,
        3 => rng.gen_range(1e-12..1e-3),
        4 => 1.0 - rng.gen_range(1e-12..1e-3),
        _ => rng.gen_range(0.0..1.0),
    }
}

/// A colour belief's marginals after event `at` of a valid stream: each
/// in [0, 1], summing to the red count k.
pub fn check_marginals(p: &[f64], k: usize, at: usize) -> Result<(), TestCaseError> {
    prop_assert!(
        p.iter().all(|x| x.is_finite() && (0.0..=1.0).contains(x)),
        "marginals out of [0, 1] after event {}: {:?}",
        at,
        p
    );
    let sum: f64 = p.iter().sum();
    prop_assert!(
        (sum - k as f64).abs() < 1e-6 * (1.0 + k as f64),
        "marginals sum to {} ≠ k = {} after event {}",
        sum,
        k,
        at
    );
    Ok(())
}

/// A stream no world produced: sightings of any colour at any accuracy,
/// sure ones included, drawn without a truth behind them, so that they
/// contradict each other (two sure reds for one red target, a sure red
/// when no target is red).
pub fn contradicting_stream(n: usize, len: usize, seed: u64) -> Vec<Event> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..len)
        .map(|_| {
            let a = rng.gen_range(0..n);
            if n >= 2 && rng.gen_bool(0.5) {
                let b = (a + rng.gen_range(1..n)) % n;
                let swap = rng.gen_range(0.0..=1.0);
                return Event::Mix(Mix {
                    a: a as u32,
                    b: b as u32,
                    swap,
                });
            }
            let (red, blue) = match rng.gen_range(0..4) {
                0 => (1.0, 0.0),
                1 => (0.0, 1.0),
                2 => (rng.gen_range(0.0..1.0), 1.0),
                _ => (1.0, rng.gen_range(0.0..1.0)),
            };
            Event::Observe(Observe {
                track: a as u32,
                red,
                blue,
            })
        })
        .collect()
}
