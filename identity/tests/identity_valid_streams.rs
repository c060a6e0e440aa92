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

use idmesh_identity::{FactoredIdentity, FactoredIdentityOptions, IdentityFilter};
use proptest::prelude::*;

mod common;
use common::valid::identity_stream;

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
    let events = identity_stream(n, len, seed);
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
