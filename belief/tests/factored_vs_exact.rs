//! Property tests of the factored belief against the exact dense filter:
//! - while no component has had to be split (max_component ≥ n), it is the
//!   exact belief: marginals, normalizer, P(pair red) and the count
//!   posterior equal the dense filter's, for random event streams with red
//!   and blue sightings, certain sightings (one likelihood 0), swaps of 0, 1
//!   and in between, k known or unknown, from a known start or the prior;
//! - the first split keeps the marginals of every track it touches (the
//!   moment matching preserves the two marginal tables);
//! - with splits it stays a valid belief: marginals in [0, 1] summing to k;
//! - a rejected observation leaves the belief exactly as it was;
//! - the last two under either coupling of the splits (`Coupling`).

use idmesh_belief::DenseFilter;
use idmesh_belief::{
    Coupling, Event, FactoredBelief, FactoredOptions, Observe, PropertyFilter, SplitRule,
};
use proptest::prelude::*;

mod common;
use common::{assert_close, case, field};

fn rule() -> impl Strategy<Value = SplitRule> {
    prop_oneof![
        Just(SplitRule::Original),
        Just(SplitRule::Recent),
        (0usize..3).prop_map(|rounds| SplitRule::LeastLoss { rounds }),
    ]
}

fn coupling() -> impl Strategy<Value = Coupling> {
    prop_oneof![
        Just(Coupling::Coupled),
        Just(Coupling::Local),
        Just(Coupling::Flat)
    ]
}

/// Everything observable about a belief, to check a rejected update.
fn snapshot(f: &FactoredBelief) -> (Vec<f64>, f64, Vec<Vec<u32>>, usize) {
    (
        f.marginals().unwrap(),
        f.log_normalizer(),
        f.components(),
        f.coefficients(),
    )
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(600))]

    #[test]
    fn unsplit_factored_belief_equals_the_exact_filter((n, k, start, seed, events) in case(10, 30)) {
        let field = field(n, k, &start, seed);
        let mut exact = DenseFilter::new(field.clone()).unwrap();
        let options = FactoredOptions { max_component: 12, ..FactoredOptions::default() };
        let mut factored = FactoredBelief::with_options(field, options).unwrap();
        for event in &events {
            let repairs = (exact.repairs(), factored.stats().repairs);
            let a = exact.apply(event);
            let b = factored.apply(event);
            prop_assert!(a.is_ok() && b.is_ok(), "exact {:?} vs factored {:?} on {:?}", a, b, event);
            // What the exact filter repairs or sets aside, the factored
            // belief does too; a repair from there on differs by design
            // (the factored belief repairs the sighting's component only).
            let repaired = exact.repairs() > repairs.0;
            prop_assert_eq!(repaired, factored.stats().repairs > repairs.1, "{:?}", event);
            if repaired {
                return Ok(());
            }
            assert_close(&exact.marginals().unwrap(), &factored.marginals().unwrap(), "marginals");
        }
        prop_assert_eq!(factored.stats().splits, 0);
        prop_assert!((exact.log_normalizer() - factored.log_normalizer()).abs() < 1e-9,
            "ln Z {} vs {}", exact.log_normalizer(), factored.log_normalizer());
        let pair = [0u32, 1];
        prop_assert!((exact.prob_all_red(&pair).unwrap() - factored.prob_all_red(&pair).unwrap()).abs() < 1e-9);
        assert_close(&exact.count_posterior().unwrap(), &factored.count_posterior().unwrap(), "count");
    }

    #[test]
    fn factored_first_split_keeps_the_marginals_it_touches((n, k, start, seed, events) in case(9, 40), max in 1usize..=4, rule in rule()) {
        let field = field(n, k, &start, seed);
        let mut exact = DenseFilter::new(field.clone()).unwrap();
        let options = FactoredOptions { max_component: max, split: rule, ..FactoredOptions::default() };
        let mut factored = FactoredBelief::with_options(field, options).unwrap();
        for event in &events {
            let parts = factored.components();
            let repairs = (exact.repairs(), factored.stats().repairs);
            let a = exact.apply(event);
            let b = factored.apply(event);
            prop_assert!(a.is_ok() && b.is_ok(), "{:?} vs {:?}", a, b);
            // Before the first split both are exact, so they agree on what
            // is possible; what neither allows, both take by their repair
            // rules (or set aside, when the prior rules it out), and from
            // there on they differ by design.
            let repaired = exact.repairs() > repairs.0;
            prop_assert_eq!(repaired, factored.stats().repairs > repairs.1);
            if repaired {
                break;
            }
            if factored.stats().splits == 0 {
                assert_close(&exact.marginals().unwrap(), &factored.marginals().unwrap(), "before");
                continue;
            }
            // This event split the two components it mixed: the marginals
            // of their tracks are preserved.
            let Event::Mix(mix) = event else { unreachable!() };
            let touched: Vec<u32> = parts
                .into_iter()
                .filter(|c| c.contains(&mix.a) || c.contains(&mix.b))
                .flatten()
                .collect();
            let (p, q) = (exact.marginals().unwrap(), factored.marginals().unwrap());
            for &t in &touched {
                prop_assert!((p[t as usize] - q[t as usize]).abs() < 1e-9,
                    "track {}: {:?} vs {:?} (touched {:?})", t, p, q, touched);
            }
            break;
        }
    }

    #[test]
    fn factored_with_splits_stays_a_valid_belief((n, k, start, seed, events) in case(16, 60), max in 1usize..=5, rule in rule(), coupling in coupling()) {
        let field = field(n, k, &start, seed);
        let options = FactoredOptions { max_component: max, split: rule, coupling, ..FactoredOptions::default() };
        let mut factored = FactoredBelief::with_options(field.clone(), options).unwrap();
        for event in &events {
            // Every event is taken: a sure sighting the belief ruled out
            // by the repair rule, one the prior rules out set aside.
            factored.apply(event).map_err(|e| TestCaseError::fail(format!("{e} on {event:?}")))?;
            // The local rule reads only the observed component: a certain
            // sighting only the red count rules out is taken, and the
            // query answers by the contradiction rule.
            let p = factored.marginals().map_err(|e| TestCaseError::fail(format!("{e} after {event:?}")))?;
            prop_assert!(p.iter().all(|x| (0.0..=1.0).contains(x)), "{:?}", p);
            if let Some(k) = field.red.known() {
                prop_assert!((p.iter().sum::<f64>() - k as f64).abs() < 1e-9, "{:?}", p);
            }
            prop_assert!(factored.components().iter().all(|c| c.len() <= max));
            // Under the contradiction rule the evidence is truly nil.
            let contradicted = factored.query_repairs() > 0;
            prop_assert!(contradicted || factored.log_normalizer().is_finite());
        }
    }

    #[test]
    fn factored_takes_or_sets_aside_every_sure_sighting((n, k, start, seed, events) in case(8, 30), max in 1usize..=12, track in 0u32..8, red in any::<bool>(), coupling in coupling()) {
        let track = track % n as u32;
        let field = field(n, k, &start, seed);
        let options = FactoredOptions { max_component: max, coupling, ..FactoredOptions::default() };
        let mut factored = FactoredBelief::with_options(field, options).unwrap();
        for event in &events {
            let _ = factored.apply(event);
        }
        let (r, b) = if red { (1.0, 0.0) } else { (0.0, 1.0) };
        let (want, other) = if red { (1.0, 0.0) } else { (0.0, 1.0) };
        let contradicted = factored.query_repairs();
        let before = snapshot(&factored);
        if factored.query_repairs() > contradicted {
            // Sightings the count ruled out were taken and the belief is
            // answered by the contradiction rule already.
            return Ok(());
        }
        let p = before.0[track as usize];
        let repairs = factored.stats().repairs;
        // A sure sighting is never refused.
        factored.observe(Observe { track, red: r, blue: b }).map_err(|e| TestCaseError::fail(e.to_string()))?;
        let now = factored.marginals().map_err(|e| TestCaseError::fail(e.to_string()))?;
        if factored.stats().repairs > repairs {
            // The belief held it impossible: the track was certainly the
            // other colour. Smoothed, the sighting wins; set aside (the
            // prior rules it out), nothing moves.
            prop_assert!((p - other).abs() < 1e-9, "p = {}", p);
            // (Under the local rule the smoothed component may now
            // contradict others, which the query answers by its rule.)
            let moved = (now[track as usize] - want).abs() < 1e-9;
            let contradicts = factored.query_repairs() > contradicted;
            prop_assert!(moved || contradicts || snapshot(&factored) == before, "now {:?}", now);
        } else if factored.query_repairs() > contradicted {
            // Only the count rules it out, which the local rule does not
            // read: the track was certainly the other colour under the
            // whole belief.
            prop_assert!(coupling.is_local());
            prop_assert!((p - other).abs() < 1e-9, "p = {}", p);
        } else {
            prop_assert!((now[track as usize] - want).abs() < 1e-9, "now {:?}", now);
        }
    }
}
