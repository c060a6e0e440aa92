//! The factored identity belief on long *valid* streams: a hidden truth
//! (which identity each track carries, and whether each mix swapped its
//! two targets) is drawn along with the stream, so every read has a
//! positive likelihood under the truth and the exact filter would never
//! run out of mass. Reads of every accuracy the trace format allows are
//! drawn — sure ones (accuracy 1, always of the true identity), good and
//! poor ones, ones no better than a guess — and wrong ones (a read of
//! another identity, with the likelihood (1 − accuracy)/(n − 1) the format
//! gives it). Mixes are mostly of neighbours, as crowds mix, with swap
//! probabilities from 0 to 1, near-ties and near-certainties included.
//! Fields of up to a few hundred tracks, thousands of events, under the
//! default options and under small caps, hard cuts and no certainty
//! threshold (which cut, link and drop far more often).
//!
//! Whatever the options, the belief must take every event and answer rows
//! that are probability distributions: an approximation may be far from
//! the exact filter, but it may not halt on a stream the world could have
//! produced.

use idmesh_belief::identity::{
    FactoredIdentity, FactoredIdentityOptions, Identify, IdentityEvent, IdentityFilter,
};
use idmesh_belief::Mix;
use proptest::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// A valid stream of `len` events on `n` tracks, from the known start
/// "track t carries identity t".
fn valid_stream(n: usize, len: usize, seed: u64) -> Vec<IdentityEvent> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut truth: Vec<u32> = (0..n as u32).collect();
    // Each stream favours a few accuracies, so that long runs of sure or of
    // poor reads happen, as they do in one deployment.
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
    ];
    let favoured: Vec<f64> = (0..3)
        .map(|_| accuracies[rng.gen_range(0..accuracies.len())])
        .collect();
    let reads = rng.gen_range(0.05..0.6);
    let mut events = Vec::with_capacity(len);
    for _ in 0..len {
        if n >= 2 && !rng.gen_bool(reads) {
            let a = rng.gen_range(0..n);
            let b = if rng.gen_bool(0.8) {
                (a + rng.gen_range(1..n.min(6))) % n
            } else {
                (a + rng.gen_range(1..n)) % n
            };
            let swap = match rng.gen_range(0..8) {
                0 => 0.0,
                1 => 1.0,
                2 => 1e-9,
                3 => 1.0 - 1e-9,
                4 => 0.5,
                _ => rng.gen_range(0.0..=1.0),
            };
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

/// Every row of the answer sums to one and holds probabilities.
fn check_rows(belief: &FactoredIdentity, n: usize, at: usize) -> Result<(), TestCaseError> {
    let answer = belief
        .sparse_marginals()
        .map_err(|e| TestCaseError::fail(format!("no answer after event {at}: {e}")))?;
    for t in 0..n {
        let row = &answer.rows()[t];
        let total = row.total(n);
        prop_assert!(
            (total - 1.0).abs() < 1e-6,
            "row {} sums to {} after event {} ({} repairs)",
            t,
            total,
            at,
            belief.repairs()
        );
        prop_assert!(row.rest.is_finite() && row.rest >= 0.0);
        for &(_, p) in &row.listed {
            prop_assert!(p.is_finite() && (-1e-12..=1.0 + 1e-9).contains(&p));
        }
    }
    Ok(())
}

fn options(choice: u8) -> FactoredIdentityOptions {
    let default = FactoredIdentityOptions::default();
    match choice {
        0 => default,
        1 => FactoredIdentityOptions {
            max_group: 3,
            ..default
        },
        2 => FactoredIdentityOptions {
            max_group: 5,
            certain: 0.0,
            ..default
        },
        _ => FactoredIdentityOptions {
            max_group: 4,
            linked: false,
            ..default
        },
    }
}

fn run(n: usize, len: usize, seed: u64, choice: u8) -> Result<(), TestCaseError> {
    let start: Vec<u32> = (0..n as u32).collect();
    let mut belief = FactoredIdentity::from_assignment(&start, options(choice))
        .map_err(|e| TestCaseError::fail(e.to_string()))?;
    let events = valid_stream(n, len, seed);
    let every = (len / 8).max(1);
    for (at, event) in events.into_iter().enumerate() {
        if let Err(e) = belief.apply(&event) {
            return Err(TestCaseError::fail(format!(
                "event {at} ({event:?}) of a valid stream was refused: {e}"
            )));
        }
        if at % every == every - 1 {
            check_rows(&belief, n, at)?;
        }
    }
    check_rows(&belief, n, len)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// Small fields, long streams: every group fills and is cut again and
    /// again.
    #[test]
    fn small_fields_take_every_valid_event(
        n in 2usize..24,
        len in 100usize..2500,
        seed in any::<u64>(),
        choice in 0u8..4,
    ) {
        run(n, len, seed, choice)?;
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(12))]

    /// Fields of a few hundred tracks: long chains of linked groups.
    #[test]
    fn large_fields_take_every_valid_event(
        n in 50usize..320,
        len in 1000usize..4000,
        seed in any::<u64>(),
        choice in 0u8..4,
    ) {
        run(n, len, seed, choice)?;
    }
}
