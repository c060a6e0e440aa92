//! Property tests: with nothing pruned, the Radon engine is exact — its
//! marginals, normalizer and set probabilities equal the dense filter's over
//! every admissible red set, for random event streams with red and blue
//! sightings, certain sightings (one likelihood 0) and swaps of 0 and 1, in
//! both the paper's signed dictionary and our positive one, for k known or
//! unknown, from a known start or the uniform prior. Approximations are
//! checked against the same exact filter: they stay valid beliefs and are
//! exact whenever their budget is never reached.

use idmesh_belief::DenseFilter;
use idmesh_belief::{
    BeliefError, Event, Field, Mix, Observe, PropertyFilter, RadonBelief, RadonOptions, RedCount,
    Sparsify, TrackSet,
};
use proptest::prelude::*;

mod common;
use common::{assert_close, field, Start};

fn case() -> impl Strategy<Value = (usize, usize, Start, u64, Vec<Event>, bool)> {
    common::case(10, 24).prop_flat_map(|(n, k, start, seed, events)| {
        (
            Just(n),
            Just(k),
            Just(start),
            Just(seed),
            Just(events),
            any::<bool>(),
        )
    })
}

/// Applies one event to both; they must agree on whether it was possible.
fn step(exact: &mut DenseFilter, radon: &mut dyn PropertyFilter, event: &Event) -> bool {
    let a = exact.apply(event);
    let b = radon.apply(event);
    match (&a, &b) {
        (Ok(()), Ok(())) => true,
        (
            Err(BeliefError::ImpossibleObservation { .. }),
            Err(BeliefError::ImpossibleObservation { .. }),
        ) => false,
        _ => panic!("exact {a:?} vs radon {b:?} on {event:?}"),
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(1000))]

    #[test]
    fn radon_without_pruning_equals_the_exact_filter((n, k, start, seed, events, signed) in case()) {
        let field = field(n, k, &start, seed);
        let mut exact = DenseFilter::new(field.clone()).unwrap();
        let options = RadonOptions { signed, ..RadonOptions::default() };
        let mut radon = RadonBelief::with_options(field, options).unwrap();
        for event in &events {
            step(&mut exact, &mut radon, event);
            assert_close(&exact.marginals().unwrap(), &radon.marginals().unwrap(), "marginals");
        }
        prop_assert!((exact.log_normalizer() - radon.log_normalizer()).abs() < 1e-9);
        let pair = TrackSet::from_tracks([0, 1]);
        let p_exact = exact.prob_all_red(&[0, 1]).unwrap();
        prop_assert!((p_exact - radon.prob_all_red(&pair).unwrap()).abs() < 1e-9);
        if matches!(start, Start::UnknownCount) {
            assert_close(&exact.count_posterior().unwrap(), &radon.count_posterior().unwrap(), "count");
        }
        if !signed {
            prop_assert!(radon.coefficients_iter().all(|(_, c)| c > 0.0));
        }
    }

    #[test]
    fn rollup_preserves_total_mass((n, k, start, seed, events, signed) in case()) {
        let options = RadonOptions { signed, ..RadonOptions::default() };
        let mut radon = RadonBelief::with_options(field(n, k, &start, seed), options).unwrap();
        for event in &events {
            let before = radon.log_normalizer();
            let is_mix = matches!(event, Event::Mix(_));
            let _ = radon.apply(event);
            if is_mix {
                prop_assert!((radon.log_normalizer() - before).abs() < 1e-9);
            }
        }
    }

    #[test]
    fn a_certain_sighting_removes_every_set_that_disagrees((n, k, start, seed, events, signed) in case(), t in 0u32..8, red in any::<bool>()) {
        let t = t % n as u32;
        let options = RadonOptions { signed, ..RadonOptions::default() };
        let mut radon = RadonBelief::with_options(field(n, k, &start, seed), options).unwrap();
        for event in &events {
            let _ = radon.apply(event);
        }
        let (r, b) = if red { (1.0, 0.0) } else { (0.0, 1.0) };
        let set_aside = radon.stats().set_aside;
        let taken = radon.observe(Observe { track: t, red: r, blue: b });
        // (A sighting the prior rules out is set aside.)
        if taken.is_ok() && radon.stats().set_aside == set_aside {
            let p = radon.marginals().unwrap()[t as usize];
            prop_assert!((p - if red { 1.0 } else { 0.0 }).abs() < 1e-9, "p = {}", p);
        }
    }

    #[test]
    fn approximations_stay_valid_and_are_exact_below_their_budget((n, k, start, seed, events, _signed) in case(), budget in 1usize..40, omp in any::<bool>()) {
        let field = field(n, k, &start, seed);
        let mut exact = DenseFilter::new(field.clone()).unwrap();
        let sparsify = if omp { Sparsify::overcomplete(budget) } else { Sparsify::threshold(budget) };
        let options = RadonOptions { sparsify: Some(sparsify), ..RadonOptions::default() };
        let mut radon = RadonBelief::with_options(field.clone(), options).unwrap();
        let mut pruned = false;
        for event in &events {
            let a = exact.apply(event);
            let b = radon.apply(event);
            pruned |= radon.stats().thresholdings + radon.stats().omp_runs > 0;
            match (a, b) {
                (Ok(()), Ok(())) => {}
                // An approximation may rule out what is still possible (and
                // then reject a sighting), never the other way round.
                (Ok(()), Err(BeliefError::ImpossibleObservation { .. })) if pruned => break,
                (Err(BeliefError::ImpossibleObservation { .. }), Err(BeliefError::ImpossibleObservation { .. })) => {}
                // A budgeted belief cannot tell an impossible sighting from
                // one its pruning lost: it takes both by its rule (a share
                // moved to the uniform belief), and the two part ways.
                (Err(BeliefError::ImpossibleObservation { .. }), Ok(())) if radon.stats().restorations > 0 => break,
                (a, b) => panic!("exact {a:?} vs approximation {b:?}"),
            }
            prop_assert!(radon.coefficients() <= budget);
            let p = radon.marginals().unwrap();
            prop_assert!(p.iter().all(|x| (-1e-9..=1.0 + 1e-9).contains(x)), "{:?}", p);
            if let Some(k) = field.red.known() {
                prop_assert!((p.iter().sum::<f64>() - k as f64).abs() < 1e-9);
            }
            if !pruned {
                assert_close(&exact.marginals().unwrap(), &p, "unpruned approximation");
            }
        }
    }
}

#[test]
fn unknown_count_certain_sightings_agree() {
    let field = Field {
        tracks: 2,
        red: RedCount::unknown_uniform(2),
        initial_red: None,
    };
    let mut exact = DenseFilter::new(field.clone()).unwrap();
    let mut radon = RadonBelief::new(field).unwrap();
    let events = [
        Event::Observe(Observe {
            track: 0,
            red: 0.27,
            blue: 0.20,
        }),
        Event::Observe(Observe {
            track: 1,
            red: 1.0,
            blue: 0.0,
        }),
        Event::Mix(Mix {
            a: 0,
            b: 1,
            swap: 0.96,
        }),
        Event::Observe(Observe {
            track: 0,
            red: 0.44,
            blue: 0.52,
        }),
        Event::Observe(Observe {
            track: 1,
            red: 0.8,
            blue: 0.2,
        }),
        Event::Observe(Observe {
            track: 0,
            red: 1.0,
            blue: 0.0,
        }),
    ];
    for event in &events {
        step(&mut exact, &mut radon, event);
        assert_close(
            &exact.marginals().unwrap(),
            &radon.marginals().unwrap(),
            "marginals",
        );
    }
}

#[test]
fn a_known_start_with_an_unknown_count_is_that_set_exactly() {
    let field = Field {
        tracks: 5,
        red: RedCount::unknown_uniform(5),
        initial_red: Some(vec![1, 3]),
    };
    let exact = DenseFilter::new(field.clone()).unwrap();
    let radon = RadonBelief::new(field).unwrap();
    assert_close(
        &exact.marginals().unwrap(),
        &radon.marginals().unwrap(),
        "start",
    );
    assert_close(
        &radon.marginals().unwrap(),
        &[0.0, 1.0, 0.0, 1.0, 0.0],
        "delta",
    );
}
