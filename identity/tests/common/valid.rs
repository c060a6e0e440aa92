//! Random *valid* identity streams: drawn with a hidden truth, so that
//! every event has a positive likelihood under it and the exact filter
//! would never run out of mass. Mixes draw their partners and swap
//! probabilities as the property beliefs' valid streams do
//! ([`super::drawn`]).

use super::drawn::{partner, swap_probability};
use idmesh_belief::Mix;
use idmesh_identity::{Identify, IdentityEvent};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// A valid identity stream of `len` events on `n` tracks, from the known
/// start "track t carries identity t".
pub fn identity_stream(n: usize, len: usize, seed: u64) -> Vec<IdentityEvent> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut truth: Vec<u32> = (0..n as u32).collect();
    let accuracies = [
        1.0,
        0.999_999,
        0.99,
        0.9,
        0.7,
        0.5,
        0.2,
        1.0 / n as f64,
        1e-6,
        1e-12,
    ];
    let favoured: Vec<f64> = (0..3)
        .map(|_| accuracies[rng.gen_range(0..accuracies.len())])
        .collect();
    let reads = rng.gen_range(0.05..0.6);
    let mut events = Vec::with_capacity(len);
    for _ in 0..len {
        if n >= 2 && !rng.gen_bool(reads) {
            let a = rng.gen_range(0..n);
            let b = partner(&mut rng, n, a);
            let swap = swap_probability(&mut rng);
            if rng.gen_bool(swap) {
                truth.swap(a, b);
            }
            events.push(IdentityEvent::Mix(Mix {
                a: a as u32,
                b: b as u32,
                swap,
            }));
        } else {
            let track = rng.gen_range(0..n);
            let accuracy = if rng.gen_bool(0.8) {
                favoured[rng.gen_range(0..favoured.len())]
            } else {
                rng.gen_range(1e-9..=1.0)
            };
            // A read is right with its accuracy; a sure read always is.
            let right = accuracy >= 1.0 || n == 1 || rng.gen_bool(accuracy);
            let identity = if right {
                truth[track]
            } else {
                (truth[track] + rng.gen_range(1..n as u32)) % n as u32
            };
            events.push(IdentityEvent::Identify(Identify {
                track: track as u32,
                identity,
                accuracy,
            }));
        }
    }
    events
}
