//! The identity filters on long *valid* streams: a hidden truth (which
//! identity each track carries) is drawn along with the stream and every
//! mix swaps it with the mix's own probability, so every event has a
//! positive likelihood under the truth and the exact filter would never
//! run out of mass. The property filters' are idmesh-belief's
//! `tests/baseline_valid_streams.rs`, whose partners and swap
//! probabilities these streams draw too.
//!
//! Identity reads of every accuracy in (0, 1]: a read of accuracy 1 is
//! always of the true identity, any other read is wrong as often as its
//! accuracy says. Mixes are mostly of neighbours, as crowds mix, with swap
//! probabilities from 0 to 1, near-ties and near-certainties included.
//! Sizes go up to what each method supports: N ≤ 7 for the exact filter,
//! a few dozen tracks for the matrices and the property bits; thousands of
//! events.
//!
//! Whatever the method, it must take every event and answer a normalized
//! belief: identity rows finite, in [0, 1] and summing to 1. An
//! approximation may be far from the exact filter, but it may not halt on
//! a stream the world could have produced.

use idmesh_belief::{RadonOptions, Sparsify};
use idmesh_identity::KNOWN_START_CONFIDENCE;
use idmesh_identity::{
    BeliefMatrix, BitCode, ExactPermutationFilter, IdentityEvent, IdentityFilter,
    InformationMatrix, InformationOptions, MarginalMethod, PropertyBitsFilter,
};
use proptest::prelude::*;

mod common;
use common::valid::identity_stream;

fn check_rows(p: &[Vec<f64>], at: usize) -> Result<(), TestCaseError> {
    for (t, row) in p.iter().enumerate() {
        prop_assert!(
            row.iter()
                .all(|x| x.is_finite() && (-1e-12..=1.0 + 1e-9).contains(x)),
            "row {} out of [0, 1] after event {}: {:?}",
            t,
            at,
            row
        );
        let total: f64 = row.iter().sum();
        prop_assert!(
            (total - 1.0).abs() < 1e-6,
            "row {} sums to {} after event {}",
            t,
            total,
            at
        );
    }
    Ok(())
}

/// Runs an identity stream through `filter`, checking the rows `checks`
/// times along the way and at the end.
fn run_identities(
    filter: &mut dyn IdentityFilter,
    events: &[IdentityEvent],
    checks: usize,
) -> Result<(), TestCaseError> {
    let every = (events.len() / checks.max(1)).max(1);
    for (i, e) in events.iter().enumerate() {
        if let Err(err) = filter.apply(e) {
            return Err(TestCaseError::fail(format!(
                "event {i} ({e:?}) of a valid stream was refused: {err}"
            )));
        }
        if i % every == every - 1 || i + 1 == events.len() {
            let p = filter.marginals().map_err(|err| {
                TestCaseError::fail(format!("no marginals after event {i} ({e:?}): {err}"))
            })?;
            check_rows(&p, i)?;
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// The exact identity filter: N ≤ 7, from a known or the uniform start.
    #[test]
    fn exact_identity_takes_every_valid_stream(
        n in 1usize..=7,
        len in 100usize..=1500,
        seed in any::<u64>(),
        known in any::<bool>(),
    ) {
        let events = identity_stream(n, len, seed);
        let start: Vec<u32> = (0..n as u32).collect();
        let mut filter = if known {
            ExactPermutationFilter::from_assignment(&start).unwrap()
        } else {
            ExactPermutationFilter::uniform(n).unwrap()
        };
        run_identities(&mut filter, &events, 16)?;
    }

    /// The information matrix, from the exact known start or the uniform
    /// one, marginals by the default method.
    #[test]
    fn information_matrix_takes_every_valid_stream(
        n in 1usize..=40,
        len in 100usize..=2000,
        seed in any::<u64>(),
        known in any::<bool>(),
    ) {
        let events = identity_stream(n, len, seed);
        let start: Vec<u32> = (0..n as u32).collect();
        let options = InformationOptions { marginals: MarginalMethod::Auto, ..InformationOptions::default() };
        let mut filter = if known {
            InformationMatrix::from_assignment(&start, KNOWN_START_CONFIDENCE, options).unwrap()
        } else {
            InformationMatrix::uniform_with(n, options).unwrap()
        };
        run_identities(&mut filter, &events, 4)?;
    }

    /// The belief matrix (Sinkhorn after every read).
    #[test]
    fn belief_matrix_takes_every_valid_stream(
        n in 1usize..=40,
        len in 100usize..=2000,
        seed in any::<u64>(),
        known in any::<bool>(),
    ) {
        let events = identity_stream(n, len, seed);
        let start: Vec<u32> = (0..n as u32).collect();
        let mut filter = if known {
            BeliefMatrix::from_assignment(&start).unwrap()
        } else {
            BeliefMatrix::uniform(n).unwrap()
        };
        run_identities(&mut filter, &events, 8)?;
    }

    /// Identities coded by property bits, one budgeted Radon belief per bit.
    #[test]
    fn property_bits_take_every_valid_stream(
        n in 2usize..=32,
        len in 100usize..=1500,
        seed in any::<u64>(),
        known in any::<bool>(),
        budget in 1usize..=200,
    ) {
        let events = identity_stream(n, len, seed);
        let start: Vec<u32> = (0..n as u32).collect();
        let code = BitCode::new(n, BitCode::min_bits(n)).unwrap();
        let options = RadonOptions {
            sparsify: Some(Sparsify::threshold(budget)),
            ..RadonOptions::default()
        };
        let mut filter =
            PropertyBitsFilter::new(code, known.then_some(start.as_slice()), options).unwrap();
        run_identities(&mut filter, &events, 8)?;
    }
}
